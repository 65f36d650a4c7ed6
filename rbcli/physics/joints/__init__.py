"""Joints: constraint rows on the maximal state, solved with Lagrange multipliers (docs/joint_solver.md)."""
