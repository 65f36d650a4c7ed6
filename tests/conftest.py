"""Shared test helpers: build scenes in Python without YAML."""

from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest

from rbcli.scene.spec import BodySpec, RecordSpec, SceneSpec, SimulationSpec

# a small asymmetric particle cloud (the tutorial's "T-handle"-like body), body frame [m] / [kg]
HANDLE_POSITIONS = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]])
HANDLE_MASSES = np.array([1.0, 0.5, 0.5, 0.25])


# Test files that compile the same heavy kernels run on one xdist worker: the joint solver's stack (~40 s
# of numba compile) and the contact search's (~25 s) are then compiled once and loaded from numba's cache,
# where two workers starting them at once both compiled them (the joint files alone: 229 CPU-s on two
# workers against 195 s on one, measured). Every other file is a unit of its own, as `--dist loadfile`
# makes it. Done by the scheduler itself (below): xdist's `--dist loadgroup` marks do nothing under
# pytest 9, whose node ids no longer read the `_nodeid` that xdist 3.8 rewrites, so each test became a
# unit of its own and the suite compiled more (measured 1,065-1,105 CPU-s against ~900).
KERNEL_FAMILIES = ("joint", "contact")


def kernel_unit(nodeid: str) -> str:
    """The scheduling unit of a test: its file, or the kernel family its file's name belongs to."""
    path = nodeid.split("::", 1)[0]
    family = next((f for f in KERNEL_FAMILIES if f in path.rsplit("/", 1)[-1]), None)
    return f"kernels-{family}" if family else path


def pytest_xdist_make_scheduler(config, log):  # noqa: ANN001, ANN201
    """xdist's file scheduling, with the units of `kernel_unit` (the controller calls this hook)."""
    from xdist.scheduler import LoadScopeScheduling

    class KernelFamilyScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return kernel_unit(nodeid)

    return KernelFamilyScheduling(config, log)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session):  # noqa: ANN001, ANN201
    """An xdist worker whose tests and session fixtures are done ignores SIGINT until it exits.

    When the run ends, execnet gives each worker 5 s to finish its session and then sends it SIGINT
    (execnet's `WorkerGateway._terminate_execution`), meant for a test still running. A worker finishing
    its unconfigure (full garbage collections of numba's objects, on a loaded machine) takes longer, and the
    KeyboardInterrupt lands wherever its main thread is, often inside a gc callback (hypothesis installs
    one), which Python prints as "Exception ignored in: ... gc_callback" on the suite's stderr although
    every test passed. No test is left to interrupt here; a worker that hangs is still ended by execnet
    10 s later (os._exit). Runs without workers (-n0) keep Ctrl-C as it is."""
    if os.environ.get("PYTEST_XDIST_WORKER") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


# Where the suite's compile time goes: RBSIM_COMPILE_LOG=DIR makes each process (each xdist worker)
# write DIR/<worker>-<pid>.jsonl, one line per test as it ends: its node id, the CPU seconds numba spent
# compiling while it ran (setup, call and teardown; only the outermost compiles: a compile inside another
# counts once) and each function compiled with its own CPU seconds.
# `python benchmarks/suite_compiles.py DIR` sums them up.
_COMPILE_LOG = os.environ.get("RBSIM_COMPILE_LOG")
# RBSIM_COMPILE_LOG_TYPES=run_chunk,find_contacts: those functions' entries carry their argument types
_COMPILE_LOG_TYPES = os.environ.get("RBSIM_COMPILE_LOG_TYPES", "")
_compiling: dict = {"stack": [], "test": "", "seconds": {}, "functions": {}}


def _install_compile_log() -> None:
    import time

    from numba.core import event

    class CompileLog(event.Listener):
        """Per test: the outermost compiles' CPU time, and each function's own (its callees' left out)."""

        def on_start(self, ev):  # noqa: ANN001, ANN202
            f = ev.data["dispatcher"].py_func
            name = f"{f.__module__}.{f.__qualname__}"
            if _COMPILE_LOG_TYPES and any(part in name for part in _COMPILE_LOG_TYPES.split(",")):
                name += f" {ev.data['args']}"  # which types made this compile another one
            _compiling["stack"].append([name, time.process_time(), 0.0])

        def on_end(self, ev):  # noqa: ANN001, ANN202
            name, started, inner = _compiling["stack"].pop()
            spent = time.process_time() - started
            test = _compiling["test"]
            _compiling["functions"].setdefault(test, []).append((name, round(spent - inner, 3)))
            if _compiling["stack"]:
                _compiling["stack"][-1][2] += spent
            else:
                _compiling["seconds"][test] = _compiling["seconds"].get(test, 0.0) + spent

    event.register("numba:compile", CompileLog())  # for the whole process (install_listener is a context)


if _COMPILE_LOG:

    def pytest_configure(config):  # noqa: ANN001, ANN201
        _install_compile_log()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_protocol(item, nextitem):  # noqa: ANN001, ANN201
        _compiling["test"] = item.nodeid
        yield
        _compiling["test"] = "(between tests)"
        _write_compile_log(item.nodeid)  # at once: a worker that crashes later loses nothing


def _write_compile_log(test: str) -> None:
    import json
    from pathlib import Path

    seconds = _compiling["seconds"].pop(test, 0.0)
    functions = _compiling["functions"].pop(test, [])
    if not seconds:
        return
    path = Path(str(_COMPILE_LOG)) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}-{os.getpid()}.jsonl"
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("a") as out:
        out.write(json.dumps({"test": test, "compile_cpu_s": seconds, "functions": functions}) + "\n")


def as_runner_passes(model, forces, data, frames) -> tuple:  # noqa: ANN001
    """A chunk loop's four tables as the runner hands them: KernelHandles (runner/simulation.py
    `_handles_of`), so a test that calls a loop itself runs the loop the runner compiled instead of
    compiling one of its own for plain tables (~6 CPU-s each on an empty cache). Keep the tuple while the
    loop runs; the arrays are written in place as with plain tables."""
    from rbcli.physics.kernel_handle import KernelHandle

    return tuple(KernelHandle(value) for value in (model, forces, data, frames))


def make_body(name: str = "b", **overrides) -> BodySpec:
    fields = dict(
        name=name,
        particle_position=HANDLE_POSITIONS,
        particle_mass=HANDLE_MASSES,
        position=np.zeros(3),
        orientation_wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
    )
    fields.update(overrides)
    return BodySpec(**fields)


def make_scene(bodies, *, dt=1e-3, duration=1.0, integrator="euler-matrix", gravity=None, every=1,
               streams=("bodies", "invariants")) -> SceneSpec:  # fmt: skip
    sim = SimulationSpec(dt=dt, duration=duration, integrator=integrator, record=RecordSpec(every, tuple(streams)))
    return SceneSpec(name="test", simulation=sim, bodies=tuple(bodies), gravity=gravity, source_text="name: test\n")


def random_bodies(count: int, seed: int = 0, **overrides) -> list[BodySpec]:
    """Bodies with random clouds, orientations, momenta (reproducible)."""
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(count):
        q = rng.normal(size=4)
        bodies.append(
            make_body(
                f"b{i}",
                particle_position=rng.normal(size=(5, 3)),
                particle_mass=rng.uniform(0.5, 2.0, size=5),
                position=rng.normal(size=3),
                orientation_wxyz=q / np.linalg.norm(q),
                velocity=rng.normal(size=3),
                angular_momentum=rng.normal(size=3),
                **overrides,
            )
        )
    return bodies


@pytest.fixture
def handle_scene():
    return make_scene([make_body("handle", angular_momentum=np.array([0.01, 0.02, 0.03]))])
