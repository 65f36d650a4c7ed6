"""Chunk loops generated from physics/pipeline.py, one module per integrator: do not edit by hand.

`python tests/physics/test_pipeline.py --regenerate` rewrites them; the test suite fails when they
differ from what the template gives.
"""
