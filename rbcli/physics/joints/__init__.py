"""Joints: constraints between bodies (or a body and the world) on the maximal state x, q, P, L.

tables.py (numpy: the JointTable of the model, the JointWork of the run's Data), rows.py
(the rows' residuals and Jacobians), solver.py + solver_graph.py (the O(n) solve of the
multipliers, Baraff 1996: docs/joint_solver.md), dense.py + dense_layout.py (a dense implementation of the
same solver interface: factor_rows, solve_rows, joint_graph, make_solver_work), rattle.py (split2's step of
a scene with joints: RATTLE, the joints' impulse by Newton through split2's drift), stages.py (the velocity
stage and the kick check of split2's loop, and the factor they share), impulses.py (what the stages share),
drives.py (motors, dampers and limits on a hinge's or slider's coordinate), cone.py (a ball joint's swing and
twist, which its cone and twist limits act on), violation.py (the per-frame
joint invariants), reference.py (numpy twins: tests and the compile-time redundancy check).
docs/joints.md has the scene format, the rows and the integration scheme.
"""
