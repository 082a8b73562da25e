"""Contact and bulk together: the coupled loop of ALGORITHM.md §6, each iteration a Newton
step of the bodies with a solve of the contact problem.

    set up every deformable body's step; find the contact nodes, normals and gaps (between
        two grains, by default, point-to-surface contacts instead, grouped in patches
        against walls: surfaces.py, patches.py, sites.py; the problem is posed on contact
        sites: nodes, points or patches); the gap
        bias b = (g + (1 − θ)Δt w_n^n)/(θΔt) keeps the end-of-step gap of the integrator's
        own displacement ≥ 0 (overlaps clipped or partly removed, gap.py); a contact loaded
        at the previous step starts closed, g = min(estimate, 0) (keep_closed)
    warm start: the impulses of the previous step at the same (node, α, β, site) enter b
    the working set: the contacts loaded at the previous step and those the bodies' first
        Newton directions bring near closing (WORKING_SET_GAP); only they enter the
        contact problem, and a contact left out that closes joins them
    repeat (iteration k):
        every body not converged: its Newton direction du = −A⁻¹ R(u; P) (A factorised)
        each body in contact: its compliance W at its contact sites (H W Hᵀ)
            Delassus: κ w [A⁻¹]_cc from that factorization;  lumped: diag(1/m)
        the contact problem (problem.py) on the rows' velocities predicted at u + du,
            solved (solvers.py: semismooth Newton by default) to max(0.1 tol, FORCING ×
            its residual at the start): loose while the bodies are far from converged
        each body: the combined step du + X ΔQ = −A⁻¹ R(u; P_new) through the line search
    until the contacts' complementarity (natural-map) residual ≤ tol and every body's
    residual ≤ tol × the largest impulse; then (``end_gap_check``, the default) the point
    contacts' true end-of-step gaps g⁺ (end_gaps.py: points and surfaces moved by the
    step's u): where g⁺ is an overlap below its floor (its start gap, and at least
    −GAP_OVERLAP h) by GAP_ERROR h (past −GAP_LIMIT h by any amount: ``_short_of``),
    the constraint is moved by the error e = g⁺ − g_lin, re-evaluated
    after each solve (a fixed point on the nonlinear gap, a secant step from its second
    update: ``_end_gap_offsets``), and the loop goes on (at most
    GAP_UPDATES times a step; a gap still below its floor then makes the step
    unconverged: it moved too far for its start geometry). Without it the linearisation's
    errors stay as overlaps and add up (session 15); or until the loop stalls (no progress
    in STALL_ITERATIONS iterations, :class:`Progress`): the step is reported unconverged
    and retried shorter

Kinematic bodies take no impulse response (W = 0): their nodal velocity is their prescribed
velocity. With ``tangent = "auto"`` a body whose compliance W_s is indefinite on the
impulses its contacts can carry (the exact tangent under compression) has its Newton
matrix's negative modes mirrored when all its contacts are frictional (they hold the body
in every direction; session 28), else when a contact solve stalls on it (the projected
tangent where the mirror does not apply); all bodies switch to the projected tangent
within a step whose contact solves keep failing or that needs many iterations.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

from softgrains.contact.detection import (
    ContactNodes,
    NodalField,
    find_contact_nodes,
    node_position,
)
from softgrains.contact.end_gaps import end_gaps
from softgrains.contact.gap import (
    boundary_gaps,
    effective_gaps,
    near_points,
    oriented_normals,
)
from softgrains.contact.levers import Levers, surface_sides
from softgrains.contact.local_law import SLIP, STICK
from softgrains.contact.problem import (
    ContactProblem,
    natural_map_residual,
    residual_norm,
    row_impulses,
    velocity_scale,
)
from softgrains.contact.sites import (
    Members,
    Slots,
    point_contacts,
    subset,
    with_point_contacts,
)
from softgrains.contact.solvers import ContactSolverOptions, solve
from softgrains.contact.surfaces import select
from softgrains.errors import SimulationError
from softgrains.grid.lattice import Lattice
from softgrains.integrator.implicit import RIGID_MODES, ImpulseResponse
from softgrains.threads import over_bodies

IMPULSE_FLOOR = 1e-14  # relative to the largest momentum of a contact node
AUTO_TANGENT_ITERATIONS = 10  # tangent = "auto": projected after this many iterations
AUTO_TANGENT_FAILED_SOLVES = 2  # ... or after this many unconverged contact solves
SOLVE_TOLERANCE_FRACTION = 0.1  # each contact solve to this fraction of the loop's tolerance
FORCING = 0.01  # ... or to this fraction of its residual at the start, if that is larger
# ... and a solve stalled within this fraction of the loop's tolerance is taken as it is,
# without the fallbacks (session 25; below 1: the loop converges on the iterates' own
# residual, which the next Newton step changes)
ACCEPTABLE_FRACTION = 0.5
INDEFINITE = 1e-9  # a body's W with an eigenvalue below −this × its largest diagonal entry
# a solve on an indefinite W that a tangent switch can mend: Newton only, this many
# iterations (those that converged in a dense compaction took 9-11)
INDEFINITE_NEWTON_ITERATIONS = 20
# a body's iterate on the step's motion limit whose Newton step can take less than this
# fraction of itself stops the step (motion_bounded_step)
BOUNDED_STEP_STUCK = 1e-3
# the loop gives up on a step (unconverged: the step-size controller retries it shorter)
# when its progress measure has not fallen below STALL_DECREASE × its best in
# STALL_ITERATIONS iterations and is not falling in each of its last STALL_DESCENT
# iterations (session 21: cycles of period 2-3 that ran to the limit; the squeeze's
# excursions, up 8× and back down in 40-50 iterations, are no cycle)
STALL_ITERATIONS = 40
STALL_DECREASE = 0.9
STALL_DESCENT = 5
# ... and at once when its residuals (contacts' and bodies') repeat unchanged, to
# STUCK_RESOLUTION relative, STUCK_REPEATS times: the iteration is at a fixed point that
# is no solution (session 27: a frictional pre-compaction step whose contact solve stopped
# at 1.09 × the loop's tolerance, every fallback spent, the bodies converged: the same
# iterate 42 times, 0.3 s each, before the stall test gave up)
STUCK_REPEATS = 3
STUCK_RESOLUTION = 1e-9
# ... and when its contact solves fail (every fallback spent, short of the loop's
# tolerance) FAILED_SOLVES_IN_A_ROW times in a row, the later ones' residuals and the
# loop's measure none below STALL_DECREASE × the first one's (session 28: a dense
# frictional step near 126 σ0 whose solves stopped at 1.6-2.0e-4 against 1e-4, 0.3 s
# each, 12 times before its residuals repeated: 5.9 s, 11× the compaction's median step)
FAILED_SOLVES_IN_A_ROW = 3
# the momentum form's stiffened rotations (the auto tangent's remedy of a slow loop) stay
# while the loop makes progress with them: its measure below STALL_DECREASE × its best
# since the switch (at first: its value then) at least once in this many measures (Progress:
# one an iteration that took a step; the count starts again where the problem changes);
# else they are undone for the rest of the step (session 55: in the 100-grain
# pre-compaction, at 4e-4 s a step, loops about to converge at their 10th iteration were
# slowed by them to line-search steps of 2^-8, the measure rising 0.4% an iteration, until
# the stall test gave up 40 iterations later and the step was retried at Δt/2; on the
# quasi-static squeezes they were made for, the measure falls 10-30× at the first
# iteration after the switch, and the loop converges at the next)
STIFFENING_TRIAL = 3
# ... and once undone the loop gets this many more iterations, as many as the stall test
# gave the stiffened loop before (session 55: a 1000-grain pre-compaction step, its
# stiffening undone, went on converging at a slow linear rate, the stall test's
# "descending" every iteration, to the loop's 200 iterations, 5.5 minutes; a shorter step
# does better)
RELAXED_ITERATIONS = 40
# a failed solve whose fallbacks ended above this fraction of the stalled Newton's residual
# (they gained less than 10%) makes the loop's next solves skip them until the iteration
# changes (Progress.restart): session 37, seed 3's frictional step 270 (2222 contacts, W
# PSD with 370 null directions) spent 8 solves of ~150 Newton iterations each (0.35 s)
# whose fallbacks never moved the Newton's 1.1-1.8e-4 (the loop asked 1e-5); the step
# then converged at Δt/2. Over two whole frictional runs 14 of 341 solves with fallbacks
# gained less than 10%, and of the 13 solves after such a one in the same step, 2 met
# their tolerance only through the fallbacks. (Without fallbacks the solver's Coulomb
# Newton is not cut at FRICTIONAL_NEWTON_ITERATIONS: it runs to its own stagnation test,
# 31-37 iterations at step 270, 0.14 s a solve.)
FUTILE_FALLBACK_GAIN = 0.9
# the contact problem of a step is posed on a working set (session 29): the contacts that
# carried an impulse at the previous step and those whose gap the bodies' first Newton
# directions bring within WORKING_SET_GAP h of closing, b + w_n < WORKING_SET_GAP h/(θΔt).
# The others carry no impulse and their compliance columns are not computed; a contact
# left out whose gap closes beyond the tolerance (−(w_n + b) on the problem's velocity
# scale) joins it, with those then near closing, and the loop goes on. The frictional
# compaction near 100 σ0: 1240 contacts found, 356 loaded, ~760 in the working set; near
# 5 σ0: 740, 74, ~300 (session 29: a step 12-21% faster, 1 thread, this 2-core machine)
WORKING_SET_GAP = 0.1
# the end-of-step gap check (end_gaps.py): a point contact whose true end gap would pass
# below its floor, min(its start gap, −GAP_OVERLAP h), by GAP_ERROR h or more has its
# constraint corrected by the difference and the step solved again (a fixed point on the
# nonlinear gap, at most GAP_UPDATES times a step). The floor at half the 0.05 h
# bar leaves the linearisation's small errors alone: each correction does work P·o in the
# bookkeeping (the force acts along the start-of-step normal while the true gap stays)
# That tolerance lets an overlap deepen by up to GAP_ERROR h a step, and an error of one
# sign does so every step (a grain point sliding along the flattened, conforming surface
# of a loaded contact: −0.0016 h a step for 50 steps in the frictionless main job,
# session 24). Beyond GAP_LIMIT h an overlap may not deepen at all: any end gap below its
# floor there is corrected. A corrected constraint aims at its floor, or GAP_SETTLE h
# above its trigger where the two are closer (past the limit, where the trigger is the
# floor itself), so that the fixed point's residual (a few % of the correction) does not
# leave it below the trigger, at which alone it is accepted. (Until session 47 it was
# accepted GAP_SETTLE h below its floor, which became the next step's floor: an overlap
# past the limit crept by up to GAP_SETTLE h a step, 0.0101 → 0.0126 h in 40 steps with
# the limit at 0.01 h; tests/protocol/test_compaction.py.)
GAP_OVERLAP, GAP_ERROR, GAP_UPDATES = 0.025, 0.002, 3
GAP_LIMIT, GAP_SETTLE = 0.04, 0.0005
# the surface side of a grain pair's point contact takes its impulses' moment at its
# material's lever (levers.py; off only to measure what it does)
SURFACE_LEVERS = True


@dataclass(frozen=True)
class CouplingSettings:
    """How the loop runs: local relation, tolerance, iteration limit, what to do when the
    limit is reached (``stop``: SimulationError; ``warn``: go on and flag the step) and the
    normal. (The gap treatment is on when the caller passes ``gap_points``.)"""

    relation: str = "delassus"
    tolerance: float = 1e-4
    max_iterations: int = 200
    on_failure: str = "stop"
    normal: str = "difference"
    overlap_removal: float = 0.0  # fraction of an estimated overlap removed per step
    overlap_tolerance: float = 0.0  # overlap (in cells h) left alone by the removal
    keep_closed: bool = False  # a contact loaded at the previous step starts closed (g ≤ 0)
    end_gap_check: bool = True  # correct the point contacts by their true end-of-step gaps
    solver: str = "newton"  # contact problem solver: newton | nsgs (solvers.py)
    solver_iterations: int = 50  # per contact solve: Newton iterations or NSGS sweeps
    grain_sites: str = "surface"  # grain–grain contacts at outer points, or at shared nodes
    grain_passes: str = "auto"  # outer points of one grain of a pair or of both (one_pass_rule)
    wall_sites: str = "points"  # grain–wall contacts at shared nodes, patches or points
    # the farthest a point may move in the step (length; 0: unbounded): each body's
    # iterate is kept within it (motion_bounded_step)
    motion_limit: float = 0.0


@dataclass
class ContactDiagnostics:
    iterations: int = 0  # outer iterations (Newton updates interleaved with sweeps)
    sweeps: int = 0  # Gauss–Seidel sweeps in all
    residual: float = 0.0
    n_contacts: int = 0
    active: int = 0
    sticking: int = 0
    sliding: int = 0
    converged: bool = True
    message: str = ""
    problem: ContactProblem | None = None  # the last iteration's, kept when not converged
    wall_work: float = 0.0  # work of the kinematic walls' contact forces over the step
    dissipation: float = 0.0  # energy the contacts took out of the bodies over the step
    gap_updates: int = 0  # constraints corrected by the true end-of-step gaps (end_gaps.py)
    # work the end-gap corrections' offsets o ≤ 0 let the contact forces do, Σ P_n(−o)/Δt
    # ≥ 0: energy put in, a part of −dissipation (the force acts along the start-of-step
    # normal while the true gap is held)
    correction_work: float = 0.0
    stalled: bool = False  # stopped early by a stall test of Progress
    working_set: int = 0  # the contacts the problem was posed on (WORKING_SET_GAP)
    # times the working set grew: contacts left out that closed, corrected end gaps, a
    # solve redone on every contact
    working_set_growths: int = 0
    # times the momentum form's stiffened rotations were undone (STIFFENING_TRIAL)
    stiffenings_undone: int = 0
    # the least start-of-step gap of the grains' outer points that one pass leaves out
    # (surfaces.least_unsampled_gap; NaN: no pair took one pass)
    least_unsampled_gap: float = math.nan


@dataclass
class Progress:
    """Stall detection for the coupling loop. Its measure is
    m = max(r_c / tol_c, max_b ‖R_b‖ / threshold_b), the largest of the contact residual
    and the bodies' Newton residuals over their stopping thresholds (converged: m ≤ 1).
    The loop has stalled when m has not fallen below STALL_DECREASE × its best in
    STALL_ITERATIONS iterations and has not fallen at each of its last STALL_DESCENT
    iterations either: a cycle (contacts switching stick/slip/open in turn, a soft mode
    over- and undershot by a body's projected tangent) that more iterations do not cure,
    where a shorter step does. A loop coming steadily back down from an excursion goes on.
    It has stalled at once, too, when its residuals repeat unchanged (STUCK_REPEATS) or
    its contact solves keep failing without gain (FAILED_SOLVES_IN_A_ROW)."""

    best: float = math.inf
    since: int = 0
    recent: list[float] = field(default_factory=list)
    residuals: list[np.ndarray] = field(default_factory=list)  # the last STUCK_REPEATS
    stuck: bool = False  # stalled because the residuals repeated unchanged
    # the last FAILED_SOLVES_IN_A_ROW (failed solve's residual, measure), in a row
    failing: list[tuple[float, float]] = field(default_factory=list)
    unsolved: bool = False  # stalled because the contact solves kept failing
    # stalled because the loop had not converged RELAXED_ITERATIONS iterations after its
    # stiffened rotations were undone (set by the loop)
    slow: bool = False
    # the momentum form's stiffened rotations on trial (set by the loop; restarted with it)
    trial: _StiffeningTrial | None = None
    # a failed solve's fallbacks gained nothing (FUTILE_FALLBACK_GAIN): the next solves
    # skip them until the iteration changes
    futile_fallbacks: bool = False

    def stalled(self, measure: float, residuals: np.ndarray | None = None,
                failed_solve: float | None = None) -> bool:
        """Record this iteration's measure (and the ``residuals`` it is the largest of,
        and the residual its contact solve stopped at if it failed); True when the loop
        has stalled: no progress (see the class), the same residuals STUCK_REPEATS times
        in a row, or FAILED_SOLVES_IN_A_ROW failed contact solves in a row whose later
        residuals and measures are none 10% below the first's."""
        self.failing = ([] if failed_solve is None else
                        (self.failing + [(failed_solve, measure)])[-FAILED_SOLVES_IN_A_ROW:])
        self.unsolved = len(self.failing) == FAILED_SOLVES_IN_A_ROW and all(
            r > STALL_DECREASE * self.failing[0][0] and m > STALL_DECREASE * self.failing[0][1]
            for r, m in self.failing[1:])
        if self.unsolved:
            return True
        if residuals is not None:
            self.residuals = (self.residuals + [np.asarray(residuals, float)])[-STUCK_REPEATS:]
            self.stuck = len(self.residuals) == STUCK_REPEATS and all(
                np.allclose(r, self.residuals[0], rtol=STUCK_RESOLUTION, atol=0.0)
                for r in self.residuals[1:])
            if self.stuck:
                return True
        self.recent = (self.recent + [measure])[-STALL_DESCENT:]
        if measure < STALL_DECREASE * self.best:
            self.best, self.since = measure, 0
            return False
        self.since += 1
        descending = len(self.recent) == STALL_DESCENT and all(
            later < earlier for earlier, later in zip(self.recent[:-1], self.recent[1:],
                                                      strict=True))
        return self.since >= STALL_ITERATIONS and not descending

    def last(self) -> float:
        """The last measure recorded since the last restart (inf: none)."""
        return self.recent[-1] if self.recent else math.inf

    def restart(self) -> None:
        """Forget the best (the iteration changed: a new tangent, corrected gaps); a
        stiffening on trial starts its trial again."""
        self.best, self.since, self.recent, self.residuals = math.inf, 0, [], []
        self.failing, self.futile_fallbacks = [], False
        if self.trial is not None:
            self.trial.restart()


@dataclass
class ContactState:
    """The contacts of a step and their impulses (on α; −P on β)."""

    nodes: ContactNodes
    impulse: np.ndarray  # (n_contacts, d)
    status: np.ndarray  # OPEN / STICK / SLIP
    gap: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def keys(self) -> list[tuple[int, int, int, int]]:
        return _keys(self.nodes)


def one_pass_rule(passes: str, friction: Callable) -> Callable[[int, int], bool]:
    """Whether a grain pair (α, β) takes one pass (one grain's outer points against the
    other's surface, surfaces.sampling_side) or two: ``grain_passes`` "one" / "two" for
    every pair; "auto" one pass where the pair has friction (μ > 0), two where it has none.

    Why "auto": one pass halves the redundant sites of two (a dense frictional step
    1.5-2.5x cheaper). Without friction a loaded round grain whose surface is the master
    spun up until the surface sides' levers (levers.py, session 46) held it; with them
    frictionless one pass holds, but its loaded contacts reach the gap limit (0.040 h
    against 0.027 h with two passes on the frictionless example) and the loop takes more
    iterations (186 against 113 s there; docs/dev-notes.md, next step 000)."""
    if passes == "auto":
        return lambda a, b: float(friction(a, b)) > 0.0
    every_pair = passes == "one"
    return lambda a, b: every_pair


def _keys(nodes: ContactNodes) -> list[tuple[int, int, int, int]]:
    """(node, α, β, site) per contact: what identifies a contact from one step to the next
    (site: −1 at a node, the point's code or −2 (a patch at a wall) for surface contacts)."""
    site = nodes.site if nodes.site is not None else np.full(len(nodes), -1)
    return list(zip(nodes.node.tolist(), nodes.alpha.tolist(), nodes.beta.tolist(),
                    site.tolist(), strict=True))


def inactive_nodes(bodies: np.ndarray, local: np.ndarray, steps: dict) -> np.ndarray:
    """Whether each contact's node (``local`` in the box of body ``bodies[c]``) carries no
    unknown of that body's step (below its activity threshold); False where the body has
    no step (a wall). One lookup in the bodies' active rows laid end to end."""
    out = np.zeros(bodies.size, bool)
    if not steps or bodies.size == 0:
        return out
    ids = np.fromiter(steps, np.int64, len(steps))
    rows = [steps[int(b)].active_row for b in ids]
    start = np.full(max(int(ids.max()), int(bodies.max())) + 1, -1, np.int64)
    start[ids] = np.cumsum([0] + [r.size for r in rows[:-1]])
    first = start[bodies]
    has_step = first >= 0
    out[has_step] = np.concatenate(rows)[first[has_step] + local[has_step]] < 0
    return out


def solve_coupled(lattice: Lattice, steps: dict, fields: list[NodalField], walls: dict,
                  settings: CouplingSettings, friction: Callable, step: int, dt: float,
                  gap_points: dict | None = None, spacing: float = 0.0, reach: float = 0.0,
                  cutoff: float | None = None,
                  warm: ContactState | None = None, names: list[str] | None = None,
                  round_bodies: set[int] | frozenset = frozenset()
                  ) -> tuple[ContactState, ContactDiagnostics]:
    """Run the coupled loop; ``steps`` maps deformable body index → BodyStep (not finished).

    ``walls`` maps a kinematic body's index to (prescribed velocity, current shape): exact
    face normals against walls. ``friction(alpha, beta)`` gives μ per contact. With
    ``gap_points`` (body index → start-of-step point positions) the boundary gap of gap.py
    is used (``reach``: the stencil's; point contacts only up to a gap of ``cutoff`` where
    that is smaller: the caller's bound on the step's motion). ``warm``: the previous
    step's contacts (warm start). ``names``: body names for the messages.
    """
    contacts = find_contact_nodes(lattice, fields, {b: s for b, (_, s) in walls.items()},
                                  settings.normal)
    # a node below a body's activity threshold carries no unknown there: no contact; two
    # kinematic bodies do not interact
    deformable = np.fromiter(steps, np.int64, len(steps))
    usable = ((np.isin(contacts.alpha, deformable) | np.isin(contacts.beta, deformable))
              & ~inactive_nodes(contacts.alpha, contacts.local_alpha, steps)
              & ~inactive_nodes(contacts.beta, contacts.local_beta, steps))
    contacts = subset(contacts, usable)
    d = lattice.dim
    gaps = np.zeros(len(contacts))
    stencils, points, reported, point_contact = None, None, None, None
    unsampled = math.nan
    walls_at_points = settings.wall_sites in ("surface", "points")
    one_pass = one_pass_rule(settings.grain_passes, friction)
    if gap_points is not None and len(contacts) and (settings.grain_sites == "surface"
                                                     or walls_at_points):
        # the pairs taken at points leave the nodal set before its gaps are estimated
        contacts, points, unsampled = point_contacts(
            lattice, steps, walls if walls_at_points else {}, contacts,
            spacing, reach if cutoff is None else min(reach, cutoff),
            settings.grain_sites == "surface", one_pass, round_bodies)
        gaps = np.zeros(len(contacts))
    if gap_points is not None and len(contacts):
        X = node_position(lattice, contacts.node)
        near = near_points(contacts, X, gap_points, reach)
        at_wall = np.isin(contacts.alpha, list(walls)) | np.isin(contacts.beta, list(walls))
        contacts = replace(contacts, normal=oriented_normals(contacts, X, gap_points, near,
                                                             at_wall))
        gaps = boundary_gaps(lattice, contacts, gap_points, spacing, reach, round_bodies, near)
    if points is not None:
        contacts, gaps, reported, stencils, point_contact = with_point_contacts(
            lattice, steps, contacts, gaps, points, settings.wall_sites == "points")
    n = len(contacts)
    P = np.zeros((n, d))
    status = np.zeros(n, dtype=np.int64)
    # the surface sides of grain pairs take their impulses' moment at the material's lever
    sides = (surface_sides(points, point_contact, steps, one_pass)
             if points is not None and SURFACE_LEVERS else None)
    levers = Levers(sides, steps) if sides is not None else None
    diag = ContactDiagnostics(n_contacts=n, least_unsampled_gap=unsampled)
    if n == 0:
        for s in steps.values():
            s.solve()
        return ContactState(contacts, P, status, np.zeros(0)), diag
    mu = np.asarray(friction(contacts.alpha, contacts.beta), float)
    # every contact's sites (its velocities anywhere); the problem is posed on a working
    # set of them (WORKING_SET_GAP)
    everywhere = Slots(steps, contacts, stencils)
    wall_va, wall_vb = np.zeros((n, d)), np.zeros((n, d))  # a kinematic side's velocity
    for bodies, slot, out in ((contacts.alpha, everywhere.a_slot, wall_va),
                              (contacts.beta, everywhere.b_slot, wall_vb)):
        for wall in np.unique(bodies[slot < 0]):
            out[(slot < 0) & (bodies == wall)] = walls[int(wall)][0]
    k_total = int(everywhere.k_size.sum())
    # the gap predicted at the end of the step by the integrator's own displacement,
    # g + Δt[(1 − θ) w_n^n + θ w_n^{n+1}] ≥ 0  ⇔  w_n^{n+1} + (g + (1 − θ)Δt w_n^n)/(θΔt) ≥ 0
    theta = _velocity_weight(next(iter(steps.values())).settings)
    start = np.einsum("ci,ci->c", everywhere.relative_velocities(
        everywhere.stack(lambda body, rows: steps[body].v_n[rows]), wall_va, wall_vb),
        contacts.normal)
    # a contact that carried an impulse at the previous step ended it closed: its gap is
    # the integrator's prediction, 0, unless the fresh estimate finds an overlap. A fresh
    # estimate > 0 there is mostly its own scatter (points entering or leaving the column),
    # and clipping only overlaps turned that scatter into a ratchet (session 7).
    warm_started = warm is not None and len(warm.nodes) > 0
    if warm_started:  # the previous step's impulses at the same (node, α, β)
        previous = dict(zip(warm.keys(), warm.impulse, strict=True))
        for c, key in enumerate(_keys(contacts)):
            if key in previous:
                P[c] = previous[key]
    estimated = gaps if reported is None else reported
    if settings.keep_closed:
        gaps = np.where(np.any(P != 0.0, axis=1), np.minimum(gaps, 0.0), gaps)
    predicted = gaps + (1.0 - theta) * dt * start
    held = effective_gaps(predicted, settings.overlap_removal,
                          settings.overlap_tolerance * lattice.h)
    bias = held / (theta * dt)
    end_gap_offset = np.zeros(n)  # the end-of-step gaps' linearisation errors (end_gaps.py)
    corrected = np.zeros(n, bool)  # the contacts whose constraint carries that error
    last_update = None  # (offsets, true end gaps) at the update before (the secant's)
    # the linear constraint holds g_lin ≥ predicted − held; the true end gap's floor is
    # min(predicted, −GAP_OVERLAP h): an overlap may not deepen, nor pass GAP_OVERLAP h
    floor_gap = np.minimum(predicted, -GAP_OVERLAP * lattice.h)
    trigger_gap = _short_of(floor_gap, lattice.h)  # an end gap below: corrected
    # a corrected constraint aims at the floor, and at least GAP_SETTLE h above the trigger
    aim_gap = np.maximum(floor_gap, trigger_gap + GAP_SETTLE * lattice.h)
    slack = np.maximum(predicted - held - floor_gap, 0.0) - (aim_gap - floor_gap)

    scale = 0.0
    for slot, body in enumerate(everywhere.bodies):
        s, rows = steps[body], everywhere.rows[slot]
        scale = max(scale, float((s.m[rows, 0, None] * np.abs(s.node_velocity(rows))).max()))
    floor = IMPULSE_FLOOR * max(scale, 1e-300)

    if warm_started:
        Q = row_impulses(everywhere.a_slot, everywhere.a_col, everywhere.b_slot,
                         everywhere.b_col, everywhere.k_off, P, k_total)
        for slot, body in enumerate(everywhere.bodies):
            steps[body].add_impulses(everywhere.rows[slot],
                                     everywhere.to_rows(slot, Q[everywhere.span(slot)]))
        if levers is not None:
            levers.apply(P)

    delassus = settings.relation == "delassus"
    options = ContactSolverOptions(method=settings.solver,
                                   tolerance=SOLVE_TOLERANCE_FRACTION * settings.tolerance,
                                   max_iterations=settings.solver_iterations, floor=floor)
    done = {i: b.converged(limit=False) for i, b in steps.items()}
    failed_solves = 0
    tangent_from = 0  # the iteration of the last tangent switch
    actual_all = None  # the relative velocities at the bodies' iterate (after an update)
    in_contact = set(everywhere.bodies)
    closing_rate = WORKING_SET_GAP * lattice.h / (theta * dt)
    member = np.zeros(n, bool)  # the working set (chosen at the first iteration)
    slots = None
    left_out = None  # a contact left out that closed, when that ended the last iteration
    progress, finished = Progress(), False
    undone_at = None  # the iteration at which stiffened rotations were undone (none again)
    short_gap = None  # (contact, true end gap, floor) when the end-gap check did not settle
    for k in range(1, settings.max_iterations + 1):
        # the Newton direction of every body not converged, with the current impulses
        moving = [i for i in steps if not done[i]]
        du = dict(zip(moving, over_bodies(
            lambda i: steps[i].newton_direction(direct=delassus and i in in_contact), moving),
            strict=True))
        if slots is None:
            # the working set: the contacts that carry an impulse, and those the bodies'
            # Newton directions bring within WORKING_SET_GAP of closing (at least one)
            w_all = everywhere.relative_velocities(everywhere.stack(
                lambda body, rows, du=du: _predicted_velocity(steps[body], rows,
                                                              du.get(body))), wall_va, wall_vb)
            near = np.einsum("ci,ci->c", w_all, contacts.normal) + bias < closing_rate
            if not (member | near).any():
                near[int(np.argmin(bias))] = True
            member |= near | np.any(P != 0.0, axis=1)
            slots, ws = _working_slots(everywhere, contacts.normal, member, mu)
        psd = _update_compliances(steps, slots, set(du), delassus)
        if not psd and delassus:
            # tangent = "auto": a body whose W_s is indefinite (its exact tangent under
            # compression) and whose contacts are all frictional has its Newton matrix's
            # negative modes mirrored; its direction and W_s are redone. (Against
            # frictionless contacts a negative mode can slide along them, and mirrored it
            # stalled the quasi-static D10 squeeze at its step 5: there the exact tangent
            # converges, or the mirror after a failed solve, _switch_indefinite.)
            shifted = [body for slot, body in enumerate(slots.bodies)
                       if body in du and not slots.semidefinite[slot]
                       and slots.impulse_basis[slot] is None
                       and steps[body].mirror_negative_modes()]
            for i in shifted:
                du[i] = steps[i].newton_direction(direct=True)
            if shifted:
                psd = _update_compliances(steps, slots, set(shifted), delassus)
        # the contact rows' velocities at the end of that Newton step (linear prediction)
        V = slots.stack(lambda body, rows, du=du: _predicted_velocity(steps[body], rows,
                                                                      du.get(body)))
        posed = ws  # the contacts of this iteration's problem
        problem = _problem(slots, subset(contacts, ws), wall_va[ws], wall_vb[ws], bias[ws],
                           mu[ws], V, P[ws])
        # an inexact solve while the start is far off (a forcing term, as in inexact Newton
        # methods): the bodies' next iterate changes the problem anyway. The fallbacks
        # after a stalled Newton presume a monotone problem (W PSD; Tresca too)
        tolerance = max(options.tolerance, FORCING * residual_norm(problem, P[ws], floor=floor))
        switchable = not psd and options.method == "newton" and any(
            not ok and steps[b].can_project()
            for b, ok in zip(slots.bodies, slots.semidefinite, strict=True))
        result = solve(problem, P[ws], replace(
            options, tresca=psd, tolerance=tolerance,
            fallbacks=not switchable and not progress.futile_fallbacks,
            acceptable=max(ACCEPTABLE_FRACTION * settings.tolerance, tolerance),
            max_iterations=(min(options.max_iterations, INDEFINITE_NEWTON_ITERATIONS)
                            if switchable else options.max_iterations)))
        failed = result.residual > max(settings.tolerance, tolerance)
        if failed and (result.fallback_gain or 0.0) > FUTILE_FALLBACK_GAIN:
            progress.futile_fallbacks = True
        if failed and switchable:
            # a stalled solve on an indefinite W (seen at 450-690 iterations a solve in a
            # dense compaction, with the fallbacks): those bodies take the mirrored (or
            # projected) tangent and the iteration is redone (not counted as a failed
            # solve: that would switch every body at the next one)
            for i in _switch_indefinite(steps, slots):
                done[i] = False
            progress.restart()
            continue
        if failed and not member.all():
            # a solve that failed on the working set is redone on every contact, and the
            # step goes on with them all (session 29: two such solves in 60 dense steps, a
            # Tresca fixed point that stalled at 6-8e-4, converged on all the contacts in
            # 49-61 iterations, as without the working set; left, each cost a retried step)
            member[:] = True
            slots, ws = _working_slots(everywhere, contacts.normal, member, mu)
            diag.working_set_growths += 1
            progress.restart()
            continue
        failed_solves += failed
        if (failed_solves >= AUTO_TANGENT_FAILED_SOLVES
                or k - tangent_from >= AUTO_TANGENT_ITERATIONS):
            # tangent = "auto": an exact tangent can make W indefinite under compression
            # (the contact problem then has no unique solution) or converge slowly: the
            # projected tangent from here on (this iteration's directions are dropped).
            # A body of the momentum form has no such negative mode: it stiffens its
            # rotation (BodyStep.stiffen_rotation) only where the loop is slow, not after
            # failed solves (session 50: on the frictionless quasi-static squeeze at D/h 20
            # and 0.025 h a step, solves failing on the redundant wall sites' nearly
            # singular W stiffened it, and the next try's rotation then diverged, ×−3 an
            # iteration, until the run stopped; the rotation's ill-conditioned compliance
            # is the deformation-scale retry's, solvers.solve)
            slow = k - tangent_from >= AUTO_TANGENT_ITERATIONS
            switched = [i for i, b in steps.items()
                        if (not b.momentum_form or (slow and undone_at is None))
                        and b.use_projected_tangent()]
            if switched:
                # (a body of the momentum form stiffens its rotations instead, on trial
                # (STIFFENING_TRIAL): the switch gets as many iterations and failed solves
                # before the next one)
                failed_solves, tangent_from = 0, k
                stiffened = [i for i in switched if steps[i].momentum_form]
                before = progress.last()
                for i in switched:
                    done[i] = False
                slots.W = [None] * len(slots.W)
                progress.restart()
                if stiffened:
                    progress.trial = _StiffeningTrial(before, stiffened)
                continue
        diag.sweeps += result.iterations + result.warmup
        # the combined step: Newton direction plus the response to the impulse changes,
        # du + X ΔQ = −A⁻¹ R(u; P_new), taken with the line search
        change = problem.row_impulses(result.impulse - P[ws])
        for slot, body in enumerate(slots.bodies):
            at_sites = change[slots.span(slot)]
            q = slots.to_rows(slot, at_sites)
            if not np.any(q):
                continue
            s, rows = steps[body], slots.rows[slot]
            s.add_impulses(rows, q)
            # the response is the sites' where the body has a site map (Delassus)
            moved = at_sites if delassus and slots.H[slot] is not None else q
            du[body] = du.get(body, 0.0) + s.impulse_move(rows, moved, slots.response[slot])
        # each body's line search (its internal forces release the GIL) on the threads
        over_bodies(lambda i, du=du: steps[i].take_step(motion_bounded_step(
            steps[i], du[i], settings.motion_limit, step)), list(du))
        P[ws] = result.impulse
        status[ws] = result.status
        if levers is not None:
            levers.apply(P)
        diag.iterations = k
        # the complementarity error at the velocities the bodies now have (the predicted
        # ones unless the line search shortened a step or the relation is lumped); a
        # contact outside the working set carries no impulse: its error is the velocity
        # of a closing gap, −(w_n + b) > 0, on the problem's velocity scale, and one above
        # the tolerance makes the set grow (the loop's residual is then the larger)
        actual_all = everywhere.relative_velocities(
            everywhere.stack(lambda body, rows: steps[body].node_velocity(rows)),
            wall_va, wall_vb)
        actual = actual_all[ws]
        diag.residual = residual_norm(problem, P[ws], actual, floor)
        # a body's residual need not be finer than the impulses it carries (same units)
        p_scale = settings.tolerance * float(np.abs(P).max())
        done = {i: b.converged(limit=False, floor=p_scale * b.impulse_weight)
                for i, b in steps.items()}
        closing = np.where(member, -np.inf, -(np.einsum("ci,ci->c", actual_all,
                                                        contacts.normal) + bias))
        speed = max(float(np.linalg.norm(actual, axis=1).max()), velocity_scale(problem))
        missed = max(float(closing.max()), 0.0) / speed if speed > 0.0 else 0.0
        left_out = int(np.argmax(closing)) if missed > settings.tolerance else None
        if left_out is not None:
            # a contact left out closes: it and those now near closing join the working
            # set, and the loop goes on with the larger problem
            member |= (closing > -closing_rate) | (closing > settings.tolerance * speed)
            slots, ws = _working_slots(everywhere, contacts.normal, member, mu)
            diag.working_set_growths += 1
            diag.residual = max(diag.residual, missed)
            progress.restart()
            continue
        if diag.residual <= settings.tolerance and all(done.values()):
            if points is None or not settings.end_gap_check:
                finished = True
                break
            # the constraint is on the true end-of-step gap: where the linearised one
            # missed an overlap (a true end gap below its floor: not wherever the error
            # is negative, an open contact's too, which re-solved nearly every step),
            # correct the constraint by the error and solve again
            lone = point_contact >= 0
            at = point_contact[lone]
            true = end_gaps(select(points, lone), steps, walls, spacing, dt)
            short = true < trigger_gap[at]
            newly = _on(n, at, short)
            linear = predicted + theta * dt * np.einsum("ci,ci->c", actual_all,
                                                        contacts.normal)
            true_all = np.full(n, np.nan)
            true_all[at] = true
            offset = _end_gap_offsets(true_all, linear, slack, corrected | newly,
                                      (end_gap_offset, last_update))
            settled = np.abs(offset - end_gap_offset).max(initial=0.0) < GAP_ERROR * lattice.h
            if not short.any() and (settled or diag.gap_updates >= GAP_UPDATES):
                finished = True
                break
            if diag.gap_updates >= GAP_UPDATES:
                # the fixed point has not settled: the step's motion is too large for
                # the start-of-step geometry (seen in the pre-compaction's impact at
                # 0.2 h a step, settled at half the step): unconverged, retried shorter
                worst = int(np.nanargmin(true - floor_gap[at]))
                short_gap = (int(at[worst]), float(true[worst]), float(floor_gap[at[worst]]))
                break
            corrected |= newly
            last_update = (end_gap_offset, true_all)
            end_gap_offset = offset
            bias = (held + end_gap_offset) / (theta * dt)
            diag.gap_updates += 1
            progress.restart()
            if (corrected & ~member).any():  # a corrected contact joins the working set
                member |= corrected
                slots, ws = _working_slots(everywhere, contacts.normal, member, mu)
                diag.working_set_growths += 1
        else:
            ratios = [diag.residual / settings.tolerance] + [
                b.residual_ratio(p_scale * b.impulse_weight) for b in steps.values()]
            measure = max(ratios)
            if progress.trial is not None and progress.trial.failed(measure):
                # it did not help: the rotations as they were, for the rest of the step
                for i in progress.trial.bodies:
                    if steps[i].relax_rotation():
                        done[i] = False
                progress.trial, undone_at = None, k
                failed_solves, tangent_from = 0, k
                slots.W = [None] * len(slots.W)
                diag.stiffenings_undone += 1
                progress.restart()
                continue
            if undone_at is not None and k - undone_at >= RELAXED_ITERATIONS:
                diag.stalled = progress.slow = True  # (a shorter step does better)
                break
            if progress.stalled(measure, np.array(ratios),
                                result.residual if failed else None):
                diag.stalled = True
                break
    if not finished:
        diag.converged = False
        if short_gap is not None:  # where the end-of-step gap did not settle
            c = short_gap[0]
        elif left_out is not None:  # a contact left out of the problem that closed
            c = left_out
        else:  # where the complementarity error is largest
            c = int(posed[np.argmax(np.linalg.norm(natural_map_residual(
                problem, P[posed], None if actual_all is None else actual_all[posed]),
                axis=1))])
        a, b = int(contacts.alpha[c]), int(contacts.beta[c])
        name_a, name_b = (names[a], names[b]) if names is not None else (a, b)
        at = (node_position(lattice, contacts.node[c:c + 1])[0] if contacts.position is None
              else contacts.position[c])
        where = ", ".join(f"{x:.6g}" for x in at)
        if short_gap is not None:
            diag.message = (
                f"step {step}: the end-of-step gaps did not settle in {GAP_UPDATES} "
                f"re-solves (contact.end_gap_check): the true end gap between bodies "
                f"'{name_a}' and '{name_b}' at ({where}) is {short_gap[1] / lattice.h:.3g} h, "
                f"below its floor {short_gap[2] / lattice.h:.3g} h; the step moves the "
                "bodies too far for the contact geometry at its start: try a smaller dt (or "
                "more [simulation] retry_halvings).")
        else:
            bodies_left = [steps[i].stepper.name for i, ok in done.items() if not ok]
            diag.message = (
                f"step {step}: the contact loop "
                + ((f"stalled after {diag.iterations} iterations, its residuals unchanged in "
                    f"the last {STUCK_REPEATS}" if progress.stuck else
                    f"stalled after {diag.iterations} iterations, its contact solves failed "
                    f"in the last {FAILED_SOLVES_IN_A_ROW} (none 10% below the first)"
                    if progress.unsolved else
                    f"stalled after {diag.iterations} iterations, not converged "
                    f"{RELAXED_ITERATIONS} iterations after the bodies' stiffened rotations "
                    "were undone" if progress.slow else
                    f"stalled after {diag.iterations} iterations, no progress in the last "
                    f"{STALL_ITERATIONS}") if diag.stalled else
                   f"did not converge in {settings.max_iterations} iterations")
                + f" (complementarity residual {diag.residual:.2e} of the largest "
                f"impulse, tolerance {settings.tolerance:g}; {settings.relation} relation, "
                f"{settings.solver} contact solver; largest error between bodies '{name_a}' "
                f"and '{name_b}' at ({where})"
                + (f"; bodies whose Newton residual is above its tolerance: "
                   f"{', '.join(bodies_left[:5])}" if bodies_left else "")
                + ("); the contact problem has no solution within the tolerance at these "
                   "iterates: try a smaller dt (or more [simulation] retry_halvings)."
                   if diag.stalled and progress.unsolved else
                   "); it converges too slowly at this step: try a smaller dt (or more "
                   "[simulation] retry_halvings)." if diag.stalled and progress.slow else
                   "); a cycle that more iterations do not cure: try a smaller dt (or more "
                   "[simulation] retry_halvings)." if diag.stalled else
                   "); try a smaller dt, more contact max_iterations"
                   + (", a looser contact tolerance or local_relation = \"delassus\"."
                      if settings.relation == "lumped" else " or a looser contact tolerance.")))
        diag.problem = problem  # (the last iteration's, on its working set)
        if settings.on_failure == "stop":
            raise SimulationError(diag.message, kind="contact", step=step,
                                  body=name_a, other=name_b, contact_problem=problem)
    diag.wall_work, diag.dissipation = _contact_work(steps, slots, P[ws], wall_va[ws],
                                                     wall_vb[ws], dt,
                                                     levers.work() if levers else 0.0)
    diag.working_set = int(member.sum())
    diag.correction_work = -float(np.einsum("ci,ci->c", P, contacts.normal)
                                  @ end_gap_offset) / dt
    diag.active = int(np.sum(np.any(P != 0.0, axis=1)))
    diag.sticking = int(np.sum(status == STICK))
    diag.sliding = int(np.sum(status == SLIP))
    return ContactState(contacts, P, status, estimated), diag


def largest_step_within(a: np.ndarray, b: np.ndarray, limit: float) -> float:
    """The largest α in [0, 1] with |a_p + α b_p| ≤ limit at every row p (a_p within the
    limit): the positive root of |b|² α² + 2 a·b α + |a|² − limit² = 0, the least over
    the rows that leave the limit within the step."""
    return float(_largest_step(np.ascontiguousarray(a, float),
                               np.ascontiguousarray(b, float), float(limit)))


@njit(cache=True, inline="always")
def _leaving_root(aa, ab, bb, limit):
    """For a row with |a|² = aa, a·b = ab, |b|² = bb: the α where |a + α b| reaches the
    limit, if the row leaves it within the step (|a + b| > limit), else inf."""
    if aa + 2.0 * ab + bb > limit * limit and bb > 0.0:
        return (-ab + np.sqrt(max(ab * ab - bb * (aa - limit * limit), 0.0))) / bb
    return np.inf


@njit(cache=True)
def _largest_step(a, b, limit):
    """:func:`largest_step_within` over the rows of a and b."""
    least = np.inf
    for p in range(a.shape[0]):
        aa, ab, bb = 0.0, 0.0, 0.0
        for i in range(a.shape[1]):
            aa += a[p, i] * a[p, i]
            ab += a[p, i] * b[p, i]
            bb += b[p, i] * b[p, i]
        least = min(least, _leaving_root(aa, ab, bb, limit))
    return min(max(least, 0.0), 1.0)


@njit(cache=True, nogil=True)
def _points_motion(nodes, N, active_row, u, du, limit):
    """For the points' displacements a_p = Σ_k N_k u_k and changes b_p = Σ_k N_k du_k (u,
    du on the active rows; an inactive stencil node's value is 0): (max |a_p|², the
    largest α of :func:`largest_step_within`, max |a_p + b_p|²)."""
    n, ns = N.shape
    d = u.shape[1]
    a, b = np.empty(d), np.empty(d)
    most_a, most_reach, least = 0.0, 0.0, np.inf
    for p in range(n):
        for i in range(d):
            a[i] = 0.0
            b[i] = 0.0
            for k in range(ns):
                row = active_row[nodes[p, k]]
                if row >= 0:
                    a[i] += N[p, k] * u[row, i]
                    b[i] += N[p, k] * du[row, i]
        aa, ab, bb, reach = 0.0, 0.0, 0.0, 0.0
        for i in range(d):
            aa += a[i] * a[i]
            ab += a[i] * b[i]
            bb += b[i] * b[i]
            reach += (a[i] + b[i]) * (a[i] + b[i])
        most_a, most_reach = max(most_a, aa), max(most_reach, reach)
        least = min(least, _leaving_root(aa, ab, bb, limit))
    return most_a, min(max(least, 0.0), 1.0), most_reach


@dataclass
class _StiffeningTrial:
    """The stiffened rotations of ``bodies`` on trial (STIFFENING_TRIAL): ``best``, the
    loop's least stall measure since the switch (at first: its value before it, inf where
    none was recorded since the loop's last restart) or since the trial's last restart
    (inf), and how many measures were recorded since it last improved (``since``)."""

    best: float
    bodies: list[int]
    since: int = 0

    def failed(self, measure: float) -> bool:
        """Record an iteration's measure; True once STIFFENING_TRIAL measures in a row are
        none below STALL_DECREASE × the best before them."""
        if measure < STALL_DECREASE * self.best:
            self.best, self.since = measure, 0
            return False
        self.since += 1
        return self.since >= STIFFENING_TRIAL

    def restart(self) -> None:
        """The problem changed (Progress.restart): the trial starts again."""
        self.best, self.since = math.inf, 0


def motion_bounded_step(step, du: np.ndarray, limit: float, at: int) -> np.ndarray:
    """The body's combined step du, shortened where it would carry a point farther than
    ``limit`` from where the step started (a trust region: the step's contacts are found
    at its start, and a step that moves a point farther is undone and retried shorter
    anyway, Simulation._check_motion). Without it the quasi-static squeeze's disk, whose
    rigid rotation is an unstable mode of the discrete problem (dev-notes, #11 item 0a),
    was carried to a solution turned by 1.3 rad in one step at Δt/8 and Δt/16, and the
    step failed at every halving (session 38). An iterate already beyond the limit is
    left to the motion check. One on the limit whose step leads out (α below
    BOUNDED_STEP_STUCK) cannot go on: a SimulationError of kind "motion" with the
    step's destination over the limit (the controller halves Δt as often as that needs)."""
    # a point's displacement is a convex combination of its nodes' (N_I ≥ 0, Σ N_I = 1):
    # within the limit wherever every node's is (the light nodes at a grain's fringe often
    # are not: then the points', by one kernel)
    if limit <= 0.0 or ((step.u + du) ** 2).sum(axis=1).max(initial=0.0) <= limit * limit:
        return du
    most_a, alpha, most_reach = _points_motion(step.nodes, step.N, step.active_row, step.u,
                                               du, float(limit))
    # (an iterate this method put on the limit may read a round-off beyond it)
    if most_a > (1.0 + 1e-9) * limit * limit:
        return du
    if alpha < BOUNDED_STEP_STUCK:
        reach = float(np.sqrt(most_reach))
        raise SimulationError(
            f"step {at}: body '{step.stepper.name}' would move a point "
            f"{reach / limit:.3g} × [simulation] max_step_motion in the step (its iterate "
            "is held at the limit and its Newton step leads out): retrying with a smaller "
            "dt.", kind="motion", step=at, body=step.stepper.name, motion=reach / limit)
    return du if alpha == 1.0 else alpha * du


def _working_slots(everywhere: Slots, normal: np.ndarray, member: np.ndarray,
                   mu: np.ndarray) -> tuple[Slots, np.ndarray]:
    """The slots (sites, maps, compliances to come) of the contacts in ``member``, and
    their indices."""
    chosen = np.flatnonzero(member)
    slots = everywhere.restricted(chosen)
    # (the chosen normals and μ taken once, and each body's contacts from one sort: per
    # body they read every contact, O(bodies × contacts), 0.4 s a step at 1000 grains)
    first, second = Members(slots.a_slot), Members(slots.b_slot)
    normal, mu = normal[chosen], mu[chosen]
    slots.impulse_basis = [_impulse_basis(slots, slot, (first(slot), second(slot)), normal,
                                          mu) for slot in range(len(slots.bodies))]
    return slots, chosen


def _update_compliances(steps: dict, slots: Slots, fresh: set, delassus: bool) -> bool:
    """Each body's compliance W_s at its contact sites where it is not known yet or its
    Newton matrix changed (the bodies ``fresh``); whether every W_s is positive
    semidefinite on the impulses its contacts can carry (``_impulse_basis``; where A is
    SPD it is: a projected tangent, or A factorised by Cholesky; otherwise checked)."""
    def update(slot: int) -> tuple[ImpulseResponse | None, np.ndarray, np.ndarray, bool]:
        body, H = slots.bodies[slot], slots.H[slot] if delassus else None
        step = steps[body]
        response, W = step.contact_response(slots.rows[slot], delassus, H)
        rigid = (step.rigid_modes(slots.rows[slot], H) if delassus  # (lumped: none)
                 else np.zeros((slots.sites(slot), slots.d, RIGID_MODES[slots.d])))
        W = W if H is not None else slots.compliance(slot, W)
        return response, W, rigid, (not delassus or step.projected
                                    or (response is not None and response.positive_definite)
                                    or _semidefinite(W, slots.impulse_basis[slot]))

    stale = [slot for slot, body in enumerate(slots.bodies)
             if slots.W[slot] is None or (delassus and body in fresh)]
    for slot, (response, W, rigid, semidefinite) in zip(stale, over_bodies(update, stale),
                                                         strict=True):
        slots.response[slot], slots.W[slot], slots.rigid[slot] = response, W, rigid
        slots.semidefinite[slot] = semidefinite
    return all(slots.semidefinite)


def _switch_indefinite(steps: dict, slots: Slots) -> list[int]:
    """``tangent = "auto"``, after a failed contact solve: the bodies whose W_s is
    indefinite (an exact tangent under compression) take the mirrored negative modes
    (session 28: the frictionless dense band −21%, half the coupling iterations, against
    the projected tangent), or the projected tangent where the mirror does not apply
    (a body above MIRROR_LIMIT unknowns); their W_s is dropped. Returns them."""
    switched = []
    for slot, body in enumerate(slots.bodies):
        if slots.semidefinite[slot]:
            continue
        if steps[body].mirror_negative_modes() or steps[body].use_projected_tangent():
            slots.W[slot] = None
            switched.append(body)
    return switched


def _impulse_basis(slots: Slots, slot: int, touching: tuple[np.ndarray, np.ndarray],
                   normal: np.ndarray, mu: np.ndarray) -> np.ndarray | None:
    """Vectors spanning the impulses body ``slot``'s contacts (``touching``: those where it
    is the first body, and the second) can carry, in its W_s's (column, component) order:
    every component at a column with a frictional contact, the normals at the others (a
    frictionless contact carries no tangential impulse, so W_s's tangential part is no
    part of the problem). None: every component."""
    d, k = slots.d, int(slots.k_size[slot])
    a, b = touching
    contact, column = np.r_[a, b], np.r_[slots.a_col[a], slots.b_col[b]]
    frictional = np.zeros(k, bool)
    frictional[column[mu[contact] > 0.0]] = True
    if frictional.all():
        return None
    full = np.flatnonzero(frictional)
    normal_only = ~frictional[column]
    basis = np.zeros((k * d, full.size * d + int(normal_only.sum())))
    basis[(full[:, None] * d + np.arange(d)).ravel(), np.arange(full.size * d)] = 1.0
    at = column[normal_only]
    basis[at[:, None] * d + np.arange(d), full.size * d + np.arange(at.size)[:, None]] = \
        normal[contact[normal_only]]
    return basis


def _semidefinite(W: np.ndarray, basis: np.ndarray | None = None) -> bool:
    """Whether the symmetric part of W (on the span of ``basis``: Bᵀ W B) has no
    eigenvalue below −INDEFINITE × max diag."""
    if basis is not None:
        W = basis.T @ W @ basis
    scale = float(np.abs(np.diagonal(W)).max(initial=0.0))
    if scale == 0.0:
        return True
    try:
        np.linalg.cholesky(0.5 * (W + W.T) + INDEFINITE * scale * np.eye(W.shape[0]))
    except np.linalg.LinAlgError:
        return False
    return True


def _on(n: int, at: np.ndarray, which: np.ndarray) -> np.ndarray:
    """A mask over the n contacts, true at the contacts ``at[which]``."""
    mask = np.zeros(n, bool)
    mask[at[which]] = True
    return mask


def _short_of(floor: np.ndarray, h: float) -> np.ndarray:
    """The end gap below which a contact is short of its floor F: F − GAP_ERROR h, but not
    below −GAP_LIMIT h unless F is (then F itself),
        max(F − GAP_ERROR h, min(F, −GAP_LIMIT h))."""
    return np.maximum(floor - GAP_ERROR * h, np.minimum(floor, -GAP_LIMIT * h))


def _end_gap_offsets(true: np.ndarray, linear: np.ndarray, slack: np.ndarray,
                     corrected: np.ndarray, history: tuple) -> np.ndarray:
    """The next offsets o of the ``corrected`` contacts' constraints (0 elsewhere): a
    secant step on the true end gap g⁺(o) (``true``, end_gaps.py; NaN: not a point
    contact) towards its aim A (floor plus margin). The plain update o + r, r = g⁺ − A,
    is min(e + s, 0) from the error e = g⁺ − g_lin of the linearised end gap g_lin
    (``linear``) and the ``slack`` s = g_lin's bound − A: it holds g⁺ at A while e stays,
    i.e. where g⁺ moves with o as g_lin does (dg⁺/do = −1). Where two updates give the
    slope σ = Δg⁺/Δo, the step is o + ω r with ω = −1/σ (within [1/4, 2]): between two
    grains whose contact turns with the step g⁺ moved twice as fast as g_lin, and the
    plain update swung between two offsets (session 47, seed 6's step 301 of the
    frictional example: r −0.041, +0.026, −0.039 h at one contact). ``history``: the
    current offsets and, from the update before, (offsets, true end gaps) or None."""
    offset, before = history
    error = np.nan_to_num(true - linear)
    plain = np.minimum(error + slack, 0.0)
    weight = np.ones_like(plain)
    if before is not None:
        change = offset - before[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = (true - before[1]) / change
        known = np.isfinite(slope) & (slope < 0.0) & (np.abs(change) > 0.0)
        weight[known] = np.clip(-1.0 / slope[known], 0.25, 2.0)
    return np.where(corrected, np.minimum(offset + weight * (plain - offset), 0.0), 0.0)


def _predicted_velocity(step, rows: np.ndarray, du: np.ndarray | None) -> np.ndarray:
    """v^{n+1} at ``rows`` after the Newton direction du (none: at the current iterate)."""
    v = step.node_velocity(rows)
    return v if du is None else v + step.velocity_affine()[0] * du[rows]


def _contact_work(steps: dict, slots: Slots, P: np.ndarray, wall_va: np.ndarray,
                  wall_vb: np.ndarray, dt: float, lever_work: float
                  ) -> tuple[float, float]:
    """The step's wall work and contact dissipation from the contact forces P/Δt, the
    levers' impulses g_b (levers.py; ``lever_work`` = Σ_b g_b·u_b) and the displacements
    u of the step (the bodies' at their contact rows, Δt v for a wall):
        W_wall = Σ_{β wall} P·u_β/Δt − Σ_{α wall} P·u_α/Δt,
        D = −Σ_c P·(u_α − u_β)/Δt − Σ_b g_b·u_b/Δt,
    so that the deformable bodies receive W_wall − D from the contacts. (D > 0: energy
    taken out, e.g. by friction; D < 0: put in, e.g. by overlap removal.)"""
    U = slots.stack(lambda body, rows: steps[body].u[rows])
    relative = slots.relative_velocities(U, wall_va * dt, wall_vb * dt)
    wall_b, wall_a = slots.b_slot < 0, slots.a_slot < 0
    work = float(np.sum(P[wall_b] * wall_vb[wall_b]) - np.sum(P[wall_a] * wall_va[wall_a]))
    return work, -(float(np.sum(P * relative)) + lever_work) / dt


def _velocity_weight(settings) -> float:
    """θ in u = Δt[(1 − θ) v^n + θ v^{n+1}]: the θ-scheme's θ; β/γ for Newmark (exact for
    the trapezoidal rule, β/γ = ½, whose u = ½Δt(v^n + v^{n+1}); other β, γ add a term in
    a^n that is left out)."""
    return settings.beta / settings.gamma if settings.kind == "newmark" else settings.theta


def _stacked_modes(modes: list[np.ndarray], d: int) -> np.ndarray:
    """The bodies' rigid modes at their sites (BodyStep.rigid_modes, (k_s, d, m) each) in
    one (k_total, d, m) array."""
    return np.concatenate(modes) if modes else np.zeros((0, d, 0))


def _problem(slots: Slots, contacts: ContactNodes, wall_va: np.ndarray, wall_vb: np.ndarray,
             bias: np.ndarray, mu: np.ndarray, V: np.ndarray, P: np.ndarray) -> ContactProblem:
    """The contact problem at the bodies' current iterate: their row velocities V with the
    impulses P (already in them) removed, V^free = V − W Q(P)."""
    problem = ContactProblem(
        normal=contacts.normal, bias=bias, mu=mu, a_slot=slots.a_slot, a_col=slots.a_col,
        b_slot=slots.b_slot, b_col=slots.b_col, wall_va=wall_va, wall_vb=wall_vb,
        k_off=slots.k_off, k_size=slots.k_size,
        w_off=np.r_[0, np.cumsum([w.size for w in slots.W])][:-1].astype(np.int64),
        W=np.concatenate([w.ravel() for w in slots.W]), V_free=V.copy(),
        rigid=_stacked_modes(slots.rigid, V.shape[1]))
    problem.V_free -= problem.compliance_times(problem.row_impulses(P))  # nothing cached yet
    return problem
