"""The named structures that carry arguments into the numba kernels, with their numba types.

The kernels are compiled eagerly with explicit signatures (so they are cached once for
every model), which is why each structure has its numba type beside it. Inside the kernels
the functions they call travel as one named tuple too (``segment.Functions``); from Python
they come as addresses (``addresses``): numba does not convert dispatchers inside a tuple.
"""
from collections import namedtuple

from numba import types

from tswm_runtime.jit.signatures import MATRIX, VECTOR

INTS = types.int64[::1]

#: Local error tolerances and step bounds: rtol (scalar), atol (per state), hmin, hmax.
Tolerances = namedtuple("Tolerances", "rtol atol hmin hmax")
TOLERANCES = types.NamedTuple((types.float64, VECTOR, types.float64, types.float64), Tolerances)

#: What ends a segment besides t_end: per guard its direction (+1 rising, -1 falling, 0
#: both), guards within gtol of 0 count as zero, ttol widens the root time tolerance,
#: noise_band drops sign changes within a guard's integration noise, singular is the index
#: of a guard whose zero cannot be reached in t (D: hand over to the Painleve approach; -1 none),
#: hold: a stable equilibrium of an autonomous scalar segment is held up to the next guard
#: crossing in t (``steady``) instead of being stepped through.
EventSettings = namedtuple("EventSettings", "directions gtol ttol noise_band singular hold")
EVENT_SETTINGS = types.NamedTuple((INTS, types.float64, types.float64, types.boolean, types.int64,
                                   types.boolean), EventSettings)

#: Output rows: times (sorted), states (and their integral), mode and parameter vector.
Outputs = namedtuple("Outputs", "t y mode p")
OUTPUTS = types.NamedTuple((VECTOR, MATRIX, INTS, MATRIX), Outputs)

#: The event log: time; (guard, from-mode, to-mode or -1 for a stop, the breakpoint a piecewise
#: law passed, counted from 1, else 0); state after the event; for an impact (P_n, P_t, kinetic
#: energy lost, v1 before it), NaN for other events.
EventLog = namedtuple("EventLog", "t index state jump")
EVENT_LOG = types.NamedTuple((VECTOR, types.int64[:, ::1], MATRIX, MATRIX), EventLog)
INDEX_WIDTH = 4
JUMP_WIDTH = 4

#: A model's modes and guards as integers (``modes.tables``): per mode its kind (sliding,
#: stick, Filippov), flank, direction, whether the scene declares it; per mode and guard
#: the guard's direction; per guard its kind, the latch slot of p it sets (-1 none) and the
#: number of pieces of the law whose piece it latches (0 none).
ModeTables = namedtuple("ModeTables", "kind flank direction declared guard_direction guard_kind guard_latch "
                                      "guard_pieces")
MODE_TABLES = types.NamedTuple((INTS, INTS, INTS, INTS, types.int64[:, ::1], INTS, INTS, INTS), ModeTables)

#: Work arrays of one step of either method: stages K, dense-output coefficients Q, the
#: Jacobian J and df/dt, the LU factors of W = I - h d J and their pivots (Rosenbrock); for the
#: stiffness test of method auto, DOPRI5's sixth-stage state y6 and an n x n scratch M.
StepWork = namedtuple("StepWork", "K Q J dfdt LU piv y6 M")
STEP_WORK = types.NamedTuple((MATRIX, MATRIX, MATRIX, VECTOR, MATRIX, INTS, VECTOR, MATRIX), StepWork)

#: An accepted step [t_a, t_b = t_a + h]: its start state and derivative, its end state,
#: and the dense output y(t_a + theta h) = y_a + h sum_j Q[:, j] theta^(j+1).
Step = namedtuple("Step", "t_a y_a f_a h t_b y_b Q")

#: The functions a kernel calls: the method's step (``segment.attempt_function``), the
#: model's rhs, jac, guards, observe and impact, and the step method auto switches to (for
#: the others their own step again: ``segment.method_steps``), as numba first-class functions
#: (their numba type: ``segment.FUNCTIONS``).
Functions = namedtuple("Functions", "attempt rhs jac guards observe impact stiff")

#: The settings of a run (and of each segment in it): the method's code, the end time, the
#: Tolerances, and the number of step attempts allowed (a segment gets what is left).
Settings = namedtuple("Settings", "method t_end tol max_steps")
SETTINGS = types.NamedTuple((types.int64, types.float64, TOLERANCES, types.int64), Settings)

#: Where a hybrid run starts: the time, the state, its integral (size 0: none), the mode (-1:
#: chosen from the state) and the parameter vector (the run writes its latches: pass a copy).
Start = namedtuple("Start", "t y quad mode p")
START = types.NamedTuple((types.float64, VECTOR, VECTOR, types.int64, VECTOR), Start)

#: What holds through one segment: its mode, the parameter vector (latches included) and the
#: EventSettings that end it.
Segment = namedtuple("Segment", "mode p ev")

#: Where a segment starts: the time, the state and its integral (both updated in place to
#: where it ends), and the first step to try (<= 0: chosen).
State = namedtuple("State", "t y quad h")

#: The accepted steps of a run, kept so that its rows and ``Result.sol`` are evaluated after it
#: (``integration.steps``): per step f = (t_a, h, t_hi, theta_hi) (it is used on [t_a, t_hi], up to
#: theta_hi of its length h), index = (kind, segment), its start y_a and end y_hi (states and their
#: integral), its dense-output coefficients Q; per segment its mode and parameter vector (latches in
#: force); count = (steps, segments) met, which may exceed the capacity (then nothing past it is kept).
StepLog = namedtuple("StepLog", "f index y_a y_hi Q seg_mode seg_p count")
STEP_LOG = types.NamedTuple((MATRIX, types.int64[:, ::1], MATRIX, MATRIX, types.float64[:, :, ::1], INTS, MATRIX,
                             INTS), StepLog)

#: Where a run writes: the Outputs, the EventLog, the observables' running maxima (one row per
#: observable: |value|, value, t), the counters (steps, rejected, rhs calls, jac calls), the StepLog.
Record = namedtuple("Record", "out log mon counters steps")
RECORD = types.NamedTuple((OUTPUTS, EVENT_LOG, MATRIX, INTS, STEP_LOG), Record)
