"""Thread-count resolution (runner/threads.py): flag over RBSIM_THREADS over all cores, validated."""

import pytest

import rbcli.runner.threads as threads_module
from rbcli.runner.threads import (
    ENV,
    WORKER_ENV,
    XDIST_ENV,
    available_cores,
    plan_threads,
    prepare_pool,
    resolve_threads,
)


def test_default_is_every_core() -> None:
    assert resolve_threads(None, {}) == available_cores()


def test_env_used_when_no_flag_and_flag_wins() -> None:
    assert resolve_threads(None, {ENV: "1"}) == 1
    assert resolve_threads(1, {ENV: "all"}) == 1
    assert resolve_threads(None, {ENV: "all"}) == available_cores()


def test_capped_at_available_cores() -> None:
    assert resolve_threads(available_cores() + 7, {}) == available_cores()


@pytest.mark.parametrize("bad", ["0", "-2", "two", "1.5"])
def test_bad_counts_are_located_errors(bad: str) -> None:
    with pytest.raises(ValueError, match="--threads: expected a positive integer"):
        resolve_threads(bad, {})
    with pytest.raises(ValueError, match=f"{ENV}: expected a positive integer"):
        resolve_threads(None, {ENV: bad})


def test_sweep_workers_default_to_one_thread() -> None:
    assert resolve_threads(None, dict(WORKER_ENV)) == 1


def test_local_cluster_workers_get_one_kernel_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    from rbcli.sweeps.dask_runner import _worker_env

    monkeypatch.delenv(ENV, raising=False)
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    assert _worker_env() == {ENV: "1", "NUMBA_NUM_THREADS": "1"}
    monkeypatch.setenv(ENV, "2")  # the caller's own choice is handed on, not overridden
    assert _worker_env()[ENV] == "2"


@pytest.fixture
def two_cores(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(threads_module, "available_cores", lambda: 2)


def test_the_default_is_auto_and_an_explicit_count_is_obeyed(two_cores) -> None:  # noqa: ANN001
    """The default (and 'auto') leaves 1 or every core to the governor; a number or 'all', from the flag
    or RBSIM_THREADS, is fixed (no governor), and the reason says where it came from."""
    default = plan_threads(None, {})
    assert (default.count, default.auto) == (2, True) and default.why.startswith("auto")
    assert plan_threads("auto", {ENV: "1"}).auto
    assert plan_threads(None, {ENV: "auto"}).auto
    assert plan_threads(2, {}) == threads_module.ThreadPlan(2, False, "--threads 2")
    assert plan_threads("all", {}) == threads_module.ThreadPlan(2, False, "--threads all")
    assert plan_threads(None, {ENV: "1"}) == threads_module.ThreadPlan(1, False, f"{ENV}=1")


def test_sweep_and_xdist_workers_get_one_thread(two_cores) -> None:  # noqa: ANN001
    assert plan_threads(None, dict(WORKER_ENV)) == threads_module.ThreadPlan(1, False, f"{ENV}=1")
    xdist = plan_threads(None, {XDIST_ENV: "gw0"})
    assert (xdist.count, xdist.auto, xdist.why) == (1, False, "a pytest-xdist worker")
    assert plan_threads(2, {XDIST_ENV: "gw0"}).count == 2  # asked for: obeyed
    assert plan_threads(None, {XDIST_ENV: "gw0", ENV: "auto"}).auto


def test_one_core_has_no_governor(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(threads_module, "available_cores", lambda: 1)
    assert plan_threads(None, {}) == threads_module.ThreadPlan(1, False, "one core")


def test_the_wait_policy_is_set_only_where_the_user_set_none(monkeypatch: pytest.MonkeyPatch) -> None:
    """libgomp reads its wait policy when it loads: GOMP_SPINCOUNT is set before, unless the user chose one."""
    monkeypatch.setattr(threads_module, "_libgomp_loaded", lambda: False)
    env: dict[str, str] = {}
    prepare_pool(env)
    assert env == {"GOMP_SPINCOUNT": threads_module.GOMP_SPINCOUNT}
    for chosen in ({"OMP_WAIT_POLICY": "ACTIVE"}, {"GOMP_SPINCOUNT": "300000"}):
        env = dict(chosen)
        prepare_pool(env)
        assert env == chosen
    monkeypatch.setattr(threads_module, "_libgomp_loaded", lambda: True)  # too late: nothing is set
    env = {}
    prepare_pool(env)
    assert env == {}
