"""Chains of wedge stages at run time: the whole run in one compiled call (kernel.py), a drive train's
answers from a run's record (answers.py), many runs and their answers in one parallel call (batch.py),
the decision of every stage's mode at an event (rules.py), the impact of a stage with a clearance
(backlash.py), and the Python that sizes the record and builds the result (run.py). It imports jit/,
integration/ and hybrid/ (the segment kernel and the mode machine's addresses); simulation/ and sweeps/
import it."""
