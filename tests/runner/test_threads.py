"""Thread-count resolution (runner/threads.py): flag over RBSIM_THREADS over all cores, validated."""

import pytest

from rbcli.runner.threads import ENV, WORKER_ENV, available_cores, resolve_threads


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
