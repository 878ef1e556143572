"""Exact equations of motion of a planar mechanism: M(q) q'' = Q(q, q', u), x = (q, q').

The joints of :mod:`netlistdyn.devices.planar` form a tree rooted at the fixed points; every
joint places one point and adds one coordinate (a LINK its rod's angle, a SLIDER its
displacement). Walking the tree from the root gives, for every point, its position p(q),
its Jacobian J = ∂p/∂q and its velocity-product acceleration c = J' q' (so p'' = J q'' + c),
and for every frame its angle φ = φ0 + jφ·q (jφ constant):

- LINK a → b, length l: φ_b = γ + θ (hanging) or γ + π − θ (upright), γ gravity's direction;
  p_b = p_a + l u(φ_b), J_b = J_a + l u⊥(φ_b) jφ_bᵀ, c_b = c_a − l ω_b² u(φ_b);
- SLIDER a → b along the direction α (in a's frame), r = s0 + s: d = u(φ_a + α),
  p_b = p_a + r d, J_b = J_a + d e_sᵀ + r d⊥ jφ_aᵀ, c_b = c_a + 2 s' ω_a d⊥ − r ω_a² d,

with u(φ) = (cos φ, sin φ), u⊥ = (−sin φ, cos φ), ω = jφ·q'. D'Alembert's principle in these
coordinates (Lagrange's equations of the same kinetic energy) gives, exactly,

    M = Σ m Jᵀ J + Σ J_rot jφ jφᵀ,    Q = Σ Jᵀ (m g − m c) + Σ (J_b − J_a)ᵀ F_ab + Σ loads,

with F_ab the spring force −k (L − l0) e and the damper force −d (e·(p_b' − p_a')) e on b along
the unit vector e from a to b. Nothing is linearised. Every operation is complex-analytic
(no abs, no branches on the state), so the Jacobians ∂f/∂x and ∂f/∂u are taken by the
complex step, f(x + i h e_j) with h = 1e-100: the derivative to rounding (its truncation error
is h² |f'''| / 6, far below one ulp), with no subtractive cancellation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from netlistdyn.base.errors import NetlistError, SourceLocation, UsageError
from netlistdyn.circuit.netlist import GROUND, Netlist
from netlistdyn.circuit.sources import SourceValues, breakpoints
from netlistdyn.circuit.waveforms import Dc
from netlistdyn.devices.planar import PlanarCard
from netlistdyn.formulation.planarcode import MAX_GENERATED, compile_rhs, evaluate

#: Complex-step size: the derivative's truncation error h²|f'''|/6 is far below rounding.
COMPLEX_STEP = 1e-100
#: An entry of A or B within this many ulp of its column's largest is rounding of an exact zero
#: (the solve with M(q) leaves ~n·eps·cond(M) of the column there: 2e-16 in the DIPC's B).
ROUNDING_ZERO = 16 * np.finfo(float).eps
#: Relative size of a mass-matrix pivot below which a coordinate moves no mass.
SINGULAR_MASS = 1e-12


@dataclass(frozen=True)
class Joint:
    """How one point is placed.

    Attributes
    ----------
    kind : str
        ``fixed``, ``link`` or ``slider``.
    point : int
        Index of the point it places.
    parent : int
        Index of the point it hangs from (-1 for a fixed point).
    coordinate : int
        Its coordinate's index in q (-1 for a fixed point).
    length : float
        A link's rod length (m); a slider's offset s0 (m).
    offset : float
        φ0 (rad): a link's angle at q = 0; a slider's track direction in its parent's frame.
    sign : float
        ∂φ/∂q of a link (+1 hanging, −1 upright).
    position : tuple of float
        A fixed point's (x, y) (m).
    card : PlanarCard or None
        The card that placed it (None: the origin ``0``).
    """

    kind: str
    point: int
    parent: int
    coordinate: int
    length: float = 0.0
    offset: float = 0.0
    sign: float = 1.0
    position: tuple[float, float] = (0.0, 0.0)
    card: PlanarCard | None = None

    @property
    def direction(self) -> tuple[float, float]:
        """(cos, sin) of ``offset``, exact at multiples of 90 degrees (the usual vertical, track)."""
        return unit(self.offset)


def unit(angle: float) -> tuple[float, float]:
    """(cos, sin) of an angle (rad), exact at multiples of π/2 (cos(π/2) is 6e-17 in floating point)."""
    quarter = angle / (math.pi / 2)
    if abs(quarter - round(quarter)) < 1e-15:
        return ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[round(quarter) % 4]
    return (math.cos(angle), math.sin(angle))


@dataclass(frozen=True)
class Mechanism:
    """The tree of a planar netlist, resolved and checked.

    Attributes
    ----------
    path : str
        The netlist file (for messages).
    points : tuple of str
        Point names, in placing order (parents first).
    joints : tuple of Joint
        One per point, same order.
    coordinates : tuple of str
        q's names: ``x(point)`` for a slider, ``angle(link)`` for a link.
    velocities : tuple of str
        q''s names: ``v(point)``, ``omega(link)``.
    cards : tuple of PlanarCard
        The card of each coordinate.
    bodies : tuple of (int, float, float)
        (point, mass kg, inertia kg·m²).
    springs : tuple of (int, int, float, float)
        (a, b, stiffness N/m, rest length m).
    dampers : tuple of (int, int, float)
        (a, b, damping N·s/m).
    forces : tuple of (int, float, int)
        (point, direction rad, input index).
    torques : tuple of (int, int)
        (point whose frame turns, input index).
    gravity : tuple of float
        (g_x, g_y) (m/s²).
    gravity_angle : float
        Gravity's direction (rad); the vertical of the links' angles.
    inputs : tuple of PlanarCard
        The loads (PFORCE, PTORQUE), the model's inputs in order.
    """

    path: str
    points: tuple[str, ...]
    joints: tuple[Joint, ...]
    coordinates: tuple[str, ...]
    velocities: tuple[str, ...]
    cards: tuple[PlanarCard, ...]
    bodies: tuple[tuple[int, float, float], ...]
    springs: tuple[tuple[int, int, float, float], ...]
    dampers: tuple[tuple[int, int, float], ...]
    forces: tuple[tuple[int, float, int], ...]
    torques: tuple[tuple[int, int], ...]
    gravity: tuple[float, float]
    gravity_angle: float
    inputs: tuple[PlanarCard, ...]

    @property
    def state_names(self) -> tuple[str, ...]:
        """x = (q, q'): ``x(cart)``, ``angle(r1)``..., then ``v(cart)``, ``omega(r1)``..."""
        return self.coordinates + self.velocities

    @property
    def input_names(self) -> tuple[str, ...]:
        """The loads' names."""
        return tuple(c.name for c in self.inputs)


def _where(card: PlanarCard) -> str:
    return f"{card.label} at {card.loc}"


def mechanism_tree(netlist: Netlist) -> Mechanism:
    """Resolve the planar cards of ``netlist`` into a tree of joints.

    Raises
    ------
    NetlistError
        (one line, at the offending card) planar cards mixed with other elements; a duplicate
        name; a second GRAVITY; a point placed twice (a closed kinematic loop, named); a joint
        whose base is never placed or not connected to a fixed point; an unknown point or
        link; a fixed point connected to nothing; a coordinate that moves no mass.
    """
    cards = netlist.planar
    path = netlist.path
    if not cards:
        raise NetlistError("no planar cards", SourceLocation(path, 0))
    if netlist.elements:
        other = netlist.elements[0]
        raise NetlistError(
            f"{other.label}: planar cards ({_where(cards[0])}) cannot be mixed with circuit or "
            "one-dimensional mechanical elements (use PSPRING, PDAMPER, PFORCE on the planar points)",
            other.loc,
        )
    seen: dict[tuple[str, str], PlanarCard] = {}
    for card in cards:
        family = "load" if card.keyword in ("pforce", "ptorque") else card.keyword
        if family == "gravity" and (family, card.key) in seen:
            raise NetlistError(f"GRAVITY: given twice (first at {seen[(family, card.key)].loc})", card.loc)
        if (family, card.key) in seen and family != "gravity":
            raise NetlistError(
                f"{card.label}: duplicate name (first defined at {seen[(family, card.key)].loc})", card.loc
            )
        seen[(family, card.key)] = card
    placing = [c for c in cards if c.keyword in ("fixed", "link", "slider")]
    placed_by: dict[str, PlanarCard | None] = {GROUND: None}
    for card in placing:
        point = card.points[-1]
        if point in placed_by:
            raise _loop_error(card, placed_by, placing)
        placed_by[point] = card
    # parents first: a joint is placed once its base is
    order: list[str] = [GROUND]
    index = {GROUND: 0}
    joints = [Joint("fixed", 0, -1, -1)]
    pending = [c for c in placing]
    coordinates: list[str] = []
    velocities: list[str] = []
    coord_cards: list[PlanarCard] = []
    gravity_card = next((c for c in cards if c.keyword == "gravity"), None)
    g = gravity_card.value if gravity_card is not None else 0.0
    gamma = gravity_card.angle if gravity_card is not None else math.radians(-90.0)
    while pending:
        progress = False
        rest: list[PlanarCard] = []
        for card in pending:
            point = card.points[-1]
            if card.keyword == "fixed":
                joints.append(Joint("fixed", len(order), -1, -1, position=card.position, card=card))
            elif card.points[0] in index:
                parent = index[card.points[0]]
                k = len(coordinates)
                if card.keyword == "link":
                    sign = -1.0 if card.upright else 1.0
                    offset = gamma + (math.pi if card.upright else 0.0)
                    joints.append(Joint("link", len(order), parent, k, card.value, offset, sign, card=card))
                    coordinates.append(f"angle({card.name})")
                    velocities.append(f"omega({card.name})")
                else:
                    joints.append(
                        Joint("slider", len(order), parent, k, card.position[0], card.angle, card=card)
                    )
                    coordinates.append(f"x({point})")
                    velocities.append(f"v({point})")
                coord_cards.append(card)
            else:
                rest.append(card)
                continue
            index[point] = len(order)
            order.append(point)
            progress = True
        if not progress:
            card = rest[0]
            base = card.points[0]
            if base not in placed_by:
                raise NetlistError(
                    f"{card.label}: point {base} is not placed by any FIXED, LINK or SLIDER", card.loc
                )
            chain = [card]
            while chain[-1].points[0] in placed_by and placed_by[chain[-1].points[0]] not in chain:
                nxt = placed_by[chain[-1].points[0]]
                assert nxt is not None
                chain.append(nxt)
            names = " -> ".join(c.name for c in chain)
            raise NetlistError(
                f"{card.label}: not connected to any fixed point (the joints {names} place each other)",
                card.loc,
            )
        pending = rest

    def point_of(card: PlanarCard, name: str) -> int:
        if name not in index:
            raise NetlistError(f"{card.label}: unknown point {name}", card.loc)
        return index[name]

    links = {c.key: c for c in coord_cards if c.keyword == "link"}
    bodies: list[tuple[int, float, float]] = []
    springs: list[tuple[int, int, float, float]] = []
    dampers: list[tuple[int, int, float]] = []
    forces: list[tuple[int, float, int]] = []
    torques: list[tuple[int, int]] = []
    inputs: list[PlanarCard] = []
    used: set[str] = set()
    for card in cards:
        if card.keyword == "body":
            bodies.append((point_of(card, card.points[0]), card.value, card.inertia))
        elif card.keyword in ("pspring", "pdamper"):
            a, b = (point_of(card, p) for p in card.points)
            if card.keyword == "pspring":
                springs.append((a, b, card.value, -1.0 if card.rest is None else card.rest))
            else:
                dampers.append((a, b, card.value))
        elif card.keyword == "pforce":
            forces.append((point_of(card, card.points[0]), card.angle, len(inputs)))
            inputs.append(card)
        elif card.keyword == "ptorque":
            link = links.get(card.points[0])
            if link is None:
                raise NetlistError(f"{card.label}: unknown link {card.points[0]}", card.loc)
            torques.append((index[link.points[1]], len(inputs)))
            inputs.append(card)
        else:
            continue
        used.update(card.points)
    for card in placing:
        if card.keyword != "fixed":
            used.add(card.points[0])
    for card in placing:
        if card.keyword == "fixed" and card.points[0] not in used:
            raise NetlistError(f"{card.label}: connected to nothing", card.loc)
    mechanism = Mechanism(
        path,
        tuple(order),
        tuple(joints),
        tuple(coordinates),
        tuple(velocities),
        tuple(coord_cards),
        tuple(bodies),
        tuple(springs),
        tuple(dampers),
        tuple(forces),
        tuple(torques),
        (g * unit(gamma)[0], g * unit(gamma)[1]),
        gamma,
        tuple(inputs),
    )
    if springs:  # a rest length not given is the length at q = 0
        p = PlanarModel(mechanism).kinematics(np.zeros(len(coordinates)), np.zeros(len(coordinates)))[0]
        fixed = tuple(
            (a, b, k, float(np.hypot(*(p[b] - p[a]))) if rest < 0 else rest) for a, b, k, rest in springs
        )
        mechanism = replace(mechanism, springs=fixed)
    _check_masses(mechanism)
    return mechanism


def _loop_error(
    card: PlanarCard, placed_by: dict[str, PlanarCard | None], placing: list[PlanarCard]
) -> NetlistError:
    """A point placed twice: name the loop the two placing joints close."""
    point = card.points[-1]
    first = placed_by[point]

    def ancestry(start: PlanarCard | None) -> list[str]:
        trail: list[str] = []
        seen: set[int] = set()
        while start is not None and id(start) not in seen and start.keyword != "fixed":
            seen.add(id(start))
            trail.append(start.name)
            base = start.points[0]
            start = next((c for c in placing if c.points[-1] == base and c is not start), None)
        return trail

    a, b = ancestry(card), ancestry(first)
    common = [n for n in a if n in b]
    if common:
        a, b = a[: a.index(common[0])], b[: b.index(common[0])]
    loop = " -> ".join([*a, *reversed(b)]) or card.name
    where = "the origin 0" if first is None else f"{first.label} at {first.loc}"
    return NetlistError(
        f"{card.label}: closes a kinematic loop ({loop}; point {point} is already placed by {where}); "
        "closed loops are not supported: every point must be placed by exactly one FIXED, LINK or SLIDER",
        card.loc,
    )


def _check_masses(mechanism: Mechanism) -> None:
    """Refuse a coordinate that moves no mass (its row of M(0) is zero: q'' undetermined)."""
    model = PlanarModel(mechanism)
    n = len(mechanism.coordinates)
    M = model.mass_forcing(np.zeros(n), np.zeros(n), np.zeros(len(mechanism.inputs)))[0].real
    scale = max(float(np.max(np.abs(M))) if M.size else 0.0, 1e-300)
    for k, card in enumerate(mechanism.cards):
        if not M[k, k] > SINGULAR_MASS * scale:
            end = card.points[-1]
            raise NetlistError(
                f"{card.label}: moves no mass (no BODY with mass on {end} or on what hangs from it: "
                "a free point with no mass)",
                card.loc,
            )
    if n and np.linalg.cond(M) > 1 / SINGULAR_MASS:
        card = mechanism.cards[-1]
        raise NetlistError(
            f"{card.label}: the mass matrix is singular at q = 0 (a point with no mass?)", card.loc
        )


@dataclass(frozen=True)
class ChainSums:
    """M and Q in a few array operations, when no slider rides on a turning frame.

    Then every joint k adds a vector w_k(q_k) to the position of each point it moves (a link
    l·u(θ), a slider (s0 + s)·d with d fixed), so with D[b, k] = 1 when joint k moves point b,
    p = R + D W, J_b[:, k] = D[b, k] t_k (t_k = ∂w_k/∂q_k) and c_b = Σ_k D[b, k] a_k
    (a_k = −l θ'² u for a link, 0 for a slider). Summing over the bodies once for all,
    Mc = Dᵀ diag(m) D and mk = Dᵀ m:

        M = Mc ∘ (T Tᵀ) + Σ J_rot jφ jφᵀ,   Q = mk ∘ (T g) − rowsum(Mc ∘ (T Aᵀ)) + springs, dampers, loads.

    The same exact equations as the point-by-point recursion, with ~25 array operations per call.
    """

    link: NDArray[np.float64]  # 1 for a link, 0 for a slider
    base: NDArray[np.float64]  # (n, 2): a link's direction at q = 0; a slider's track
    length: NDArray[np.float64]  # a link's l; a slider's s0
    sign: NDArray[np.float64]
    Mc: NDArray[np.float64]
    mk: NDArray[np.float64]
    Mrot: NDArray[np.float64]
    gravity: NDArray[np.float64]
    spring_D: NDArray[np.float64]
    spring_R: NDArray[np.float64]
    spring_k: NDArray[np.float64]
    spring_rest: NDArray[np.float64]
    damper_D: NDArray[np.float64]
    damper_R: NDArray[np.float64]
    damper_d: NDArray[np.float64]
    force_D: NDArray[np.float64]
    force_dir: NDArray[np.float64]
    force_input: NDArray[np.intp]
    torque: NDArray[np.float64]  # (n, inputs)
    t_link: NDArray[np.float64]  # s·l of a link, 0 for a slider
    t_slider: NDArray[np.float64]  # 1 for a slider, 0 for a link
    bias: NDArray[np.float64]  # −l of a link, 0 for a slider
    D: NDArray[np.float64]  # (points, n): 1 where joint k moves the point
    R: NDArray[np.float64]  # (points, 2): the fixed part of each point's position
    turned: NDArray[np.float64]  # (2, n): base turned by 90 degrees

    @classmethod
    def of(cls, mechanism: Mechanism) -> ChainSums | None:
        """The sums of ``mechanism``; None when a slider's base turns (a link above it)."""
        joints = mechanism.joints
        n = len(mechanism.coordinates)
        count = len(mechanism.points)
        D = np.zeros((count, n))
        R = np.zeros((count, 2))
        turning = np.zeros(count, dtype=bool)
        jphi = np.zeros((count, n))
        link = np.zeros(n, dtype=bool)
        base = np.zeros((n, 2))
        length = np.zeros(n)
        sign = np.ones(n)
        for joint in joints:
            b = joint.point
            if joint.kind == "fixed":
                R[b] = joint.position
                continue
            a, k = joint.parent, joint.coordinate
            D[b] = D[a]
            D[b, k] = 1.0
            R[b] = R[a]
            length[k] = joint.length
            base[k] = joint.direction
            if joint.kind == "link":
                link[k] = True
                sign[k] = joint.sign
                turning[b] = True
                jphi[b, k] = joint.sign
            else:
                if turning[a]:
                    return None
                jphi[b] = jphi[a]
        mass = np.zeros(count)
        Mrot = np.zeros((n, n))
        for point, m, inertia in mechanism.bodies:
            mass[point] += m
            Mrot += inertia * np.outer(jphi[point], jphi[point])
        Mc = D.T @ (mass[:, None] * D)
        springs, dampers = mechanism.springs, mechanism.dampers
        ninputs = len(mechanism.inputs)
        torque = np.zeros((n, ninputs))
        for point, j in mechanism.torques:
            torque[:, j] += jphi[point]
        return cls(
            link.astype(float),
            base,
            length,
            sign,
            Mc,
            D.T @ mass,
            Mrot,
            np.array(mechanism.gravity),
            np.array([D[b] - D[a] for a, b, _, _ in springs]).reshape(len(springs), n),
            np.array([R[b] - R[a] for a, b, _, _ in springs]).reshape(len(springs), 2),
            np.array([k for _, _, k, _ in springs]),
            np.array([rest for _, _, _, rest in springs]),
            np.array([D[b] - D[a] for a, b, _ in dampers]).reshape(len(dampers), n),
            np.array([R[b] - R[a] for a, b, _ in dampers]).reshape(len(dampers), 2),
            np.array([d for _, _, d in dampers]),
            np.array([D[p] for p, _, _ in mechanism.forces]).reshape(len(mechanism.forces), n),
            np.array([unit(angle) for _, angle, _ in mechanism.forces]).reshape(len(mechanism.forces), 2),
            np.array([j for _, _, j in mechanism.forces], dtype=np.intp),
            torque,
            sign * length * link,
            1.0 - link,
            -length * link,
            D,
            R,
            np.stack([-base[:, 1], base[:, 0]]),
        )

    def positions(self, q: NDArray[Any]) -> NDArray[Any]:
        """Every point's position p = R + D W(q) (m): ``(points, 2)``."""
        ql = q * self.link
        cs, sn = np.cos(ql), self.sign * np.sin(ql)
        ex, ey = self.base[:, 0], self.base[:, 1]
        w = self.length + q * (1.0 - self.link)
        W = np.stack([w * (ex * cs - ey * sn), w * (ex * sn + ey * cs)], axis=1)
        return self.R + self.D @ W

    def mass_forcing(
        self, q: NDArray[Any], qd: NDArray[Any], u: NDArray[Any]
    ) -> tuple[NDArray[Any], NDArray[Any]]:
        """M(q) and Q(q, q', u) (see the class)."""
        ql = q * self.link  # a slider's row: cos 0 = 1, sin 0 = 0, so u is its track d
        cs, sn = np.cos(ql), self.sign * np.sin(ql)
        base, turned = self.base.T, self.turned  # (2, n): d0 = (ex, ey) and d0⊥ = (−ey, ex)
        U = base * cs + turned * sn  # (ux, uy): the rod's direction, a slider's track
        P = turned * cs - base * sn  # u⊥
        T = self.t_slider * U + self.t_link * P  # t_k = ∂w_k/∂q_k: s·l·u⊥ (link), d (slider)
        A = (self.bias * qd * qd) * U  # a_k = −l θ'² u (link), 0 (slider)
        Mc = self.Mc
        M = Mc * (T.T @ T) + self.Mrot
        Q = self.mk * (self.gravity @ T) - (Mc * (T.T @ A)).sum(1)
        tx, ty = T[0], T[1]
        ux, uy = U[0], U[1]
        if self.spring_k.size or self.damper_d.size:
            w = self.length + q * (1.0 - self.link)  # |w_k|: l (link), s0 + s (slider)
            W = np.stack([w * ux, w * uy], axis=1)
            T = np.stack([tx, ty], axis=1)
            if self.spring_k.size:
                r = self.spring_R + self.spring_D @ W
                L = np.sqrt(np.sum(r * r, axis=1))
                E = r / L[:, None]
                Q = Q - (self.spring_D * (E @ T.T)).T @ (self.spring_k * (L - self.spring_rest))
            if self.damper_d.size:
                r = self.damper_R + self.damper_D @ W
                E = r / np.sqrt(np.sum(r * r, axis=1))[:, None]
                rate = np.sum(E * ((self.damper_D * qd) @ T), axis=1)
                Q = Q - (self.damper_D * (E @ T.T)).T @ (self.damper_d * rate)
        if self.force_input.size:
            fx, fy = self.force_dir[:, 0], self.force_dir[:, 1]
            Q = (
                Q
                + (self.force_D * (np.multiply.outer(fx, tx) + np.multiply.outer(fy, ty))).T
                @ u[self.force_input]
            )
        if self.torque.size:
            Q = Q + self.torque @ u
        return M, Q


class PlanarModel:
    """M(q), Q(q, q', u), x' = f(x, u), their Jacobians, energy and point positions.

    Parameters
    ----------
    mechanism : Mechanism
    """

    def __init__(self, mechanism: Mechanism) -> None:
        self.mechanism = mechanism
        self.n = len(mechanism.coordinates)
        self.nstates = 2 * self.n
        self.ninputs = len(mechanism.inputs)
        self.stats = {"f": 0, "jac": 0}
        self.sums = ChainSums.of(mechanism)
        #: the generated straight-line rhs (real, complex) of :mod:`netlistdyn.formulation.planarcode`
        self.code = compile_rhs(self.sums) if self.sums is not None and self.n <= MAX_GENERATED else None

    def kinematics(
        self, q: NDArray[Any], qd: NDArray[Any]
    ) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[np.float64]]:
        """Per point: position p (m), Jacobian J = ∂p/∂q, bias c = J' q' (m/s²); per frame jφ.

        Returns
        -------
        p : ndarray (points, 2)
        J : ndarray (points, 2, n)
        c : ndarray (points, 2)
        jphi : ndarray (points, n)
            ∂φ/∂q of each point's frame (constant).
        """
        mech = self.mechanism
        n = self.n
        count = len(mech.points)
        dtype = np.result_type(q, qd, float)
        p = np.zeros((count, 2), dtype=dtype)
        J = np.zeros((count, 2, n), dtype=dtype)
        c = np.zeros((count, 2), dtype=dtype)
        frame = np.zeros((count, 2), dtype=dtype)  # (cos φ, sin φ) of each point's frame
        frame[:, 0] = 1.0
        jphi = np.zeros((count, n))
        for joint in mech.joints:
            b = joint.point
            if joint.kind == "fixed":
                p[b] = joint.position
                continue
            a, k = joint.parent, joint.coordinate
            if joint.kind == "link":
                jphi[b, k] = joint.sign
                omega = joint.sign * qd[k]
                cs, sn = np.cos(q[k]), joint.sign * np.sin(q[k])
                ex, ey = joint.direction  # the rod's direction at q = 0, rotated by sign·q
                u = np.array([ex * cs - ey * sn, ex * sn + ey * cs])
                frame[b] = u
                perp = np.array([-u[1], u[0]])
                p[b] = p[a] + joint.length * u
                J[b] = J[a]
                J[b, :, k] += joint.sign * joint.length * perp
                c[b] = c[a] - joint.length * omega**2 * u
            else:
                frame[b] = frame[a]
                jphi[b] = jphi[a]
                omega = jphi[a] @ qd
                tx, ty = joint.direction  # the track in the base's frame
                d = np.array([frame[a, 0] * tx - frame[a, 1] * ty, frame[a, 1] * tx + frame[a, 0] * ty])
                perp = np.array([-d[1], d[0]])
                r = joint.length + q[k]
                p[b] = p[a] + r * d
                J[b] = J[a] + r * np.outer(perp, jphi[a])
                J[b, :, k] += d
                c[b] = c[a] + 2 * qd[k] * omega * perp - r * omega**2 * d
        return p, J, c, jphi

    def mass_forcing(
        self, q: NDArray[Any], qd: NDArray[Any], u: NDArray[Any]
    ) -> tuple[NDArray[Any], NDArray[Any]]:
        """M(q) (kg, kg·m, kg·m²) and Q(q, q', u) (N, N·m): M q'' = Q.

        By :class:`ChainSums` when no slider rides on a turning frame, else by the recursion of
        :meth:`kinematics` (:meth:`tree_mass_forcing`); both are exact.
        """
        if self.sums is not None:
            return self.sums.mass_forcing(q, qd, u)
        return self.tree_mass_forcing(q, qd, u)

    def tree_mass_forcing(
        self, q: NDArray[Any], qd: NDArray[Any], u: NDArray[Any]
    ) -> tuple[NDArray[Any], NDArray[Any]]:
        """M(q) and Q(q, q', u) from :meth:`kinematics`, point by point (any tree)."""
        mech = self.mechanism
        p, J, c, jphi = self.kinematics(q, qd)
        dtype = np.result_type(p, u)
        M = np.zeros((self.n, self.n), dtype=dtype)
        Q = np.zeros(self.n, dtype=dtype)
        g = np.array(mech.gravity)
        for point, m, inertia in mech.bodies:
            Jb = J[point]
            M += m * (Jb.T @ Jb)
            Q += m * (Jb.T @ (g - c[point]))
            if inertia:
                M += inertia * np.outer(jphi[point], jphi[point])
        for a, b, k, rest in mech.springs:
            r = p[b] - p[a]
            length = np.sqrt(r @ r)
            Q -= k * (length - rest) * ((J[b] - J[a]).T @ (r / length))
        for a, b, d in mech.dampers:
            r = p[b] - p[a]
            e = r / np.sqrt(r @ r)
            Jab = J[b] - J[a]
            Q -= d * (e @ (Jab @ qd)) * (Jab.T @ e)
        for point, angle, j in mech.forces:
            Q += u[j] * (J[point].T @ np.array(unit(angle)))
        for point, j in mech.torques:
            Q += u[j] * jphi[point]
        return M, Q

    def rhs(self, x: NDArray[Any], u: NDArray[Any]) -> NDArray[Any]:
        """x' = (q', M⁻¹ Q) at state x and inputs u."""
        n = self.n
        if self.code is not None:
            real, cplx = self.code
            try:
                return evaluate(cplx if np.iscomplexobj(x) or np.iscomplexobj(u) else real, x, u)
            except (ValueError, ZeroDivisionError):  # M not positive definite here: numpy's solve says so
                pass
        M, Q = self.mass_forcing(x[:n], x[n:], u)
        return np.concatenate([x[n:], np.linalg.solve(M, Q)])

    def jacobians(
        self, x: NDArray[np.float64], u: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """∂f/∂x and ∂f/∂u at (x, u) by the complex step (exact to rounding)."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(u, dtype=float)
        A = np.empty((self.nstates, self.nstates))
        B = np.empty((self.nstates, self.ninputs))
        for j in range(self.nstates):
            xc = x.astype(complex)
            xc[j] += 1j * COMPLEX_STEP
            A[:, j] = self.rhs(xc, u).imag / COMPLEX_STEP
        for j in range(self.ninputs):
            uc = u.astype(complex)
            uc[j] += 1j * COMPLEX_STEP
            B[:, j] = self.rhs(x, uc).imag / COMPLEX_STEP
        for matrix in (A, B):  # an exact zero computed through M⁻¹ comes out as a few ulp of the column
            scale = np.max(np.abs(matrix), axis=0, initial=0.0)
            matrix[np.abs(matrix) <= ROUNDING_ZERO * scale] = 0.0
        return A, B

    def energy(self, x: NDArray[np.float64]) -> tuple[float, float]:
        """(kinetic, potential) energy (J): potential of gravity and the springs."""
        n = self.n
        q, qd = x[:n], x[n:]
        M, _ = self.mass_forcing(q, qd, np.zeros(self.ninputs))
        p = self.positions(x)
        g = np.array(self.mechanism.gravity)
        potential = -sum(m * float(g @ p[point]) for point, m, _ in self.mechanism.bodies)
        for a, b, k, rest in self.mechanism.springs:
            potential += 0.5 * k * (float(np.hypot(*(p[b] - p[a]))) - rest) ** 2
        return 0.5 * float(qd @ M @ qd), potential

    def positions(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Every point's (x, y) (m) at state x: ``(points, 2)``."""
        n = self.n
        if self.sums is not None:
            return np.asarray(self.sums.positions(x[:n]), dtype=float)
        return np.asarray(self.kinematics(x[:n], x[n:])[0], dtype=float)

    @property
    def conservative(self) -> bool:
        """No damper; loads count as inputs (conservative when they are zero)."""
        return not self.mechanism.dampers


class PlanarSystem:
    """x' = f(t, x) of a planar netlist: the model with its loads' waveforms.

    The interface of :class:`netlistdyn.formulation.nlsystem.NonlinearSystem` where the
    transients need it (``f``, ``jacobian``, ``nstates``, ``stats``).

    Parameters
    ----------
    netlist : Netlist
    span : tuple of float, optional
        (TSTEP, TSTOP) (s): the SPICE defaults of the loads' waveforms.
    """

    def __init__(self, netlist: Netlist, span: tuple[float, float] | None = None) -> None:
        self.netlist = netlist
        self.mechanism = mechanism_tree(netlist)
        self.model = PlanarModel(self.mechanism)
        self.nstates = self.model.nstates
        self.state_names = self.mechanism.state_names
        if span is None:
            span = (netlist.tran.tstep, netlist.tran.tstop) if netlist.tran is not None else (1.0, 1.0)
        self.waveforms = [
            (Dc(c.value) if c.waveform is None else c.waveform).resolved(*span) for c in self.mechanism.inputs
        ]
        self.inputs = SourceValues(self.waveforms)
        self.stats = self.model.stats

    def breakpoints(self, tstop: float) -> NDArray[np.float64]:
        """Times (s) where a load's slope jumps."""
        return breakpoints(self.waveforms, tstop)

    def f(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """x' at time t (m/s, rad/s, m/s², rad/s²)."""
        self.stats["f"] += 1
        return np.asarray(self.model.rhs(x, self.inputs(t)), dtype=float)

    def jacobian(self, t: float, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """∂f/∂x at (t, x) (complex step)."""
        self.stats["jac"] += 1
        return self.model.jacobians(x, self.inputs(t))[0]

    def outputs(self, x: NDArray[np.float64], names: Sequence[str]) -> NDArray[np.float64]:
        """Output values at state x (see :func:`output_rows`)."""
        return output_values(self.model, x, names)


def output_values(model: PlanarModel, x: NDArray[np.float64], names: Sequence[str]) -> NDArray[np.float64]:
    """The named outputs at state ``x``.

    A state's own name (``x(cart)``, ``angle(r1)``, ``v(cart)``, ``omega(r1)``); ``px(p)``,
    ``py(p)``: point p's position (m); ``x(p)``, ``y(p)`` of a point no slider places: its
    displacement from where it is at q = 0 (m), as the linear ``ROD`` netlists' ``x(bob)``.

    Raises
    ------
    UsageError
        An output the mechanism does not have.
    """
    mech = model.mechanism
    states = {s.lower(): k for k, s in enumerate(mech.state_names)}
    points = {p: k for k, p in enumerate(mech.points)}
    n = model.n
    p: NDArray[np.float64] | None = None
    p0 = None
    out = np.empty(len(names))
    for k, raw in enumerate(names):
        name = raw.lower().replace(" ", "")
        if name in states:
            out[k] = x[states[name]]
            continue
        kind, _, rest = name.partition("(")
        point = rest.rstrip(")")
        if point in ("gnd",):
            point = GROUND
        if kind in ("px", "py", "x", "y") and point in points:
            axis = 0 if kind in ("px", "x") else 1
            if p is None:
                p = model.positions(x)
            value = p[points[point], axis]
            if kind in ("x", "y"):
                if p0 is None:
                    p0 = model.positions(np.zeros(2 * n))
                value -= p0[points[point], axis]
            out[k] = value
            continue
        raise UsageError(
            f"--output {raw}: not an output of the mechanism (states: {', '.join(mech.state_names)}; "
            "or px(point), py(point), x(point), y(point))"
        )
    return out
