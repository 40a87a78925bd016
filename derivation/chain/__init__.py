"""Chains of wedge stages (worm gear -> power screw -> ...): derivation only, not yet simulated.

stages.py turns each stage's kind and geometry into an equivalent wedge (slope, friction angle,
levers); dynamics.py derives the chain's modes from each stage's kinetostatics in SymPy;
selector.py decides which mode a state is in; scene.py reads ``[[stage]]`` scene files."""
