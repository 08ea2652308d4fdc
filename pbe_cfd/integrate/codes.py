"""Codes shared by the per-cell integrators: schemes, per-cell status, statistics columns,
outcomes of one attempted step and the rows of the per-cell scratch matrix."""

# ---- schemes ([method] integrator, config[INTEGRATOR]) ------------------------------------
EXPLICIT = 0             # Bogacki-Shampine RK3(2) only
IMPLICIT = 1             # Rosenbrock RODAS3 only
AUTO = 2                 # explicit until the cell is stiff, then Rosenbrock, and back
SCHEMES = {"explicit": EXPLICIT, "implicit": IMPLICIT, "auto": AUTO}

# ---- status codes per cell ---------------------------------------------------------------
OK = 0
STEP_FLOOR = 1          # the step fell below params[STEP_FLOOR]
NOT_FINITE = 2          # the right-hand side produced a non-finite value
TOO_MANY_STEPS = 3      # the per-call step budget ran out
UNREALIZABLE_START = 4  # the state handed in was not realizable
STATUS_TEXT = {
    OK: "ok",
    STEP_FLOOR: "the step size fell below its floor",
    NOT_FINITE: "the right-hand side became non-finite",
    TOO_MANY_STEPS: "the step budget of one output interval ran out (the cell's rates are far "
                    "faster than the output interval)",
    UNREALIZABLE_START: "the initial moment set is not realizable",
}

#: accepted-or-rejected steps one cell may take within one call (one output interval)
MAX_STEPS_PER_INTERVAL = 1_000_000

# ---- statistics columns per cell (accumulated) -----------------------------------------
ACCEPTED = 0             # accepted steps (both schemes)
REJECTED_ERROR = 1       # steps rejected by the error test (or a non-finite rate)
REJECTED_REALIZABILITY = 2   # steps rejected because a stage or the result left the set
RHS_CALLS = 3            # right-hand-side evaluations, Jacobian columns included
IMPLICIT_STEPS = 4       # accepted Rosenbrock steps
JACOBIANS = 5            # Jacobians evaluated (finite differences)
SWITCHES = 6             # scheme switches of the auto integrator
EXPONENTIAL_STEPS = 7    # accepted explicit steps with the droplet capture integrated exactly
N_STATS = 8

# ---- outcome of one attempted step -------------------------------------------------------
ACCEPT = 0
REJECT_ERROR = 1
REJECT_REALIZABILITY = 2
REJECT_NOT_FINITE = 3

# ---- rows of the per-cell scratch matrix (N_BUF, n_state) -------------------------------
F0 = 0                   # d(state)/dt at the current state
KA = 1                   # stage vectors (explicit k2..k4, Rosenbrock k1..k4)
KB = 2
KC = 3
KD = 4
STAGE = 5                # stage argument
YNEW = 6                 # the candidate state of the step
FTMP = 7                 # right-hand side at a stage or a perturbed state
YTMP = 8                 # perturbed state / stage 2 / power-iteration vector
GCOL = 9                 # capture column d f / d n_d (exponential explicit step)
N_BUF = 10
