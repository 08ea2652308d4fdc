"""Codes shared by the per-cell integrators: schemes, per-cell status, statistics columns,
outcomes of one attempted step and the rows of the per-cell scratch matrix. Each group is an
ordered table of names; a name's value is its position (``physics.parameters.numbered``)."""
from ..physics.parameters import numbered

# ---- schemes ([method] integrator, config[INTEGRATOR]) ------------------------------------
SCHEME_TABLE = (
    ("EXPLICIT", "Bogacki-Shampine RK3(2) only"),
    ("IMPLICIT", "Rosenbrock RODAS3 only"),
    ("AUTO", "explicit until the cell is stiff, then Rosenbrock, and back"),
)
numbered(SCHEME_TABLE, globals())
SCHEMES = {name.lower(): globals()[name] for name, _ in SCHEME_TABLE}

# ---- status codes per cell (apart from the params slot STEP_FLOOR they report on) ---------
STATUS_TABLE = (
    ("OK", "ok"),
    ("STEP_BELOW_FLOOR", "the step size fell below its floor"),
    ("NOT_FINITE", "the right-hand side became non-finite"),
    ("TOO_MANY_STEPS", "the step budget of one output interval ran out (the cell's rates are "
                       "far faster than the output interval)"),
    ("UNREALIZABLE_START", "the initial moment set is not realizable"),
    ("METHOD_RAISED", "the method's functions raised an exception inside the integrator, so "
                      "its rates were not whole; the cell is kept at the start of the "
                      "interval"),
)
numbered(STATUS_TABLE, globals())
STATUS_TEXT = {globals()[name]: text for name, text in STATUS_TABLE}

#: accepted-or-rejected steps one cell may take within one call (one output interval)
MAX_STEPS_PER_INTERVAL = 1_000_000

# ---- statistics columns per cell (accumulated) -----------------------------------------
STATS_TABLE = (
    ("ACCEPTED", "accepted steps (both schemes)"),
    ("REJECTED_ERROR", "steps rejected by the error test (or a non-finite rate)"),
    ("REJECTED_REALIZABILITY", "steps rejected because a stage or the result left the set"),
    ("RHS_CALLS", "right-hand-side evaluations, Jacobian columns included"),
    ("IMPLICIT_STEPS", "accepted Rosenbrock steps"),
    ("JACOBIANS", "Jacobians evaluated (finite differences)"),
    ("SWITCHES", "scheme switches of the auto integrator"),
    ("EXPONENTIAL_STEPS", "accepted explicit steps with the droplet capture integrated exactly"),
    ("STOKES_EVENTS", "accepted steps across which a pair's sharp Stokes decision switched "
                      "(the next step restarts there with the new decisions)"),
    ("REJECTED_SWITCH", "steps rejected because the switch of a sharp Stokes decision within "
                        "them was not located closely enough"),
)
N_STATS = numbered(STATS_TABLE, globals())

# ---- outcome of one attempted step -------------------------------------------------------
OUTCOME_TABLE = (
    ("ACCEPT", "the step is taken"),
    ("REJECT_ERROR", "the error estimate is above the tolerance"),
    ("REJECT_REALIZABILITY", "a stage or the result is not realizable"),
    ("REJECT_NOT_FINITE", "a stage is not finite"),
    ("REJECT_SWITCH", "a sharp Stokes decision switched within the step and the step is too "
                      "long for the switching time it leaves unlocated"),
)
numbered(OUTCOME_TABLE, globals())

# ---- rows of the per-cell scratch matrix (N_BUF, n_state) -------------------------------
BUFFER_TABLE = (
    ("F0", "d(state)/dt at the current state"),
    ("KA", "stage vectors (explicit k2..k4, Rosenbrock k1..k4)"),
    ("KB", "stage vector"),
    ("KC", "stage vector"),
    ("KD", "stage vector"),
    ("STAGE", "stage argument"),
    ("YNEW", "the candidate state of the step"),
    ("FTMP", "right-hand side at a stage or a perturbed state"),
    ("YTMP", "perturbed state / stage 2 / power-iteration vector"),
    ("GCOL", "capture column d f / d n_d (exponential explicit step)"),
)
N_BUF = numbered(BUFFER_TABLE, globals())
