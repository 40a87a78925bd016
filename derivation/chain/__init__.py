"""Chains of wedge stages (worm gear -> power screw -> ...): derived here, simulated by the runtime.

stages.py turns each stage's kind and geometry into an equivalent wedge (slope, friction angle,
levers); dynamics.py derives the chain's modes from each stage's kinetostatics in SymPy;
selector.py decides which mode a state is in; clearance.py derives open stages (a clearance per stage:
rigid groups, gap kinematics, the impact; not in the generated code yet); scene.py reads ``[[stage]]`` scene files; codegen.py
emits a chain scene's numba module (tswm_runtime/chains/run.py runs it)."""
