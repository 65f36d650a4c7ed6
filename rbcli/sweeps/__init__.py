"""Sweeps and ensembles: one base scene run over many values of its parameters, on Dask.

    sweep file ─load.py─▶ SweepSpec (axes, values, numbering: spec.py) ─run.py─▶ batches ─▶ serial, or
    Dask (dask_runner.py, the only importer of dask) ─▶ execute.py: per variant scene text → scene loader
    → Simulation.run → a row ─▶ table.py: parts/*.parquet (one per batch, atomic) ─▶ results.parquet

`rbcli.sweep(...)` (run.py: `sweep`) is the Python entry point; `rbsim sweep FILE` the command. The
package is named `sweeps` because `rbcli.sweep` is the function: a subpackage of the same name would
replace it on `rbcli` as soon as it was imported. docs/sweeps.md has the file format.
"""
