"""Articulated trees in joint coordinates (docs/trees.md): the tree table (table.py), forward kinematics
and the articulated-body algorithm (aba.py, compiled) and their numpy reference (reference.py)."""
