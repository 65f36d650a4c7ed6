"""CPU ns per step of `Simulation.step` for one scene on one thread, after a 10-step warm-up, best of the
repeats; prints one line of JSON. Run it alternately on two trees to compare them under a shared load
(CPU time, fresh process each; docs/performance.md, "No speed lost to issue 44's changes"):

    PYTHONPATH=<tree> python benchmarks/step_cpu.py SCENE.yaml STEPS REPEATS
"""

import json
import sys
import time

from rbcli.runner.simulation import Simulation

path, steps, repeats = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
sim = Simulation(path, threads=1)
sim.step(10)
best = float("inf")
for _ in range(repeats):
    started = time.process_time()
    sim.step(steps)
    best = min(best, time.process_time() - started)
print(json.dumps({"scene": path.rsplit("/", 1)[-1], "ns_per_step": best / steps * 1e9}))
