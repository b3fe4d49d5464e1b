"""A listener motion graph of real frames (Okwechime 2011, §4.5.3: MIMiC on real listener motion).

The thesis's audio-driven listener maps the speaker's audio classes onto a MIMiC graph of a real
listener's motion. The shipped motion library has no listener recording, so this module takes
the listener's three motion states (:data:`~gesture_sim.signals.listener_audio.STATES`) from
the real frames it does have: **rests** (stillness), **nods** (head pitch down and up) and
**posture** shifts (a slow lean or tilt between two stillnesses), on the body joints the
listener drives (:data:`GRAPH_JOINTS`: the neck, head and spine joints of
:data:`~gesture_sim.signals.listener.LISTENER_JOINTS`; the brows and lip corners are not
retargeted into the library, so they stay with the listener's own envelopes).

**Coordinates.** Every clip's :data:`GRAPH_JOINTS` are taken relative to that clip's median
pose (its "neutral"), so excerpts of different clips and performers share one pose space and a
value of 0 is the performer's typical posture. Angles are in rad; thresholds below in degrees
(``*_deg``), degrees per second (``*_dps``) and seconds (``*_s``).

**Extraction** (:func:`extract_excerpts`, settings :class:`ExtractSettings`; per clip, on the
joint angles smoothed by a centred moving average of ``smooth_s``):

1. **Rest**: a frame is still when, over the ``rest_s``-long window centred on it, every graph
   joint ranges at most ``rest_range_deg`` and every arm joint (:data:`ARM_JOINTS`) at most
   ``rest_arm_range_deg`` (the arms and head nearly still). Runs of still frames are cut into
   consecutive pieces of ``rest_s`` (one piece's last frame is the next one's first, so
   neighbouring pieces chain exactly); a shorter remainder is dropped.
2. **Nod**: on the head pitch ``p = neck_flex + head_flex`` (> 0 down), every local maximum
   is a nod candidate. Its start is found by walking back from the peak while ``p`` keeps
   decreasing (at most ``nod_max_s``), its end by walking forward the same way (the turning
   points where the head stops) but no further than where it is back at its starting pitch,
   and the slow tails, where the pitch changes by less than ``turn_dps``, are trimmed
   off. Kept when: the way down is ``nod_min_deg``..``nod_max_deg``; the way back up
   ``return_frac``..``1 / return_frac`` of it (the head comes back near where it began); it
   lasts ``nod_min_s``..``nod_max_s``; it is mostly pitch (the head's roll and yaw,
   ``neck_* + head_*``, each range at most ``side_frac`` of the way down plus ``side_deg``);
   the spine joints range at most ``nod_spine_deg`` (not a bow); the pitch speed stays below
   ``nod_speed_dps``; it is smooth (the RMS of the raw minus the smoothed pitch at most
   ``rough_frac`` of the way down: jitter is not a nod); and it does not overlap the previous
   nod kept.
3. **Posture**: stillness as in 1 but on the graph joints alone, over ``still_s`` windows with
   ``still_range_deg``. Between two consecutive still runs ``gap_min_s``..``gap_max_s`` apart,
   the frames from the end of the first to the start of the second are a shift when the net
   change of the lean and tilt (lower-spine flexion; spine bend ``lower + upper``; head tilt
   ``neck_bend + head_bend``) has a norm of at least ``shift_min_deg`` and at least
   ``shift_share`` of the norm of the whole net change (those three, the head pitch
   ``neck_flex + head_flex`` and yaw ``neck_twist + head_twist``), that whole change is at
   most ``shift_max_deg`` (a small shift), no graph joint moves faster
   than ``shift_speed_dps``, and the path is steady (the summed path length of the graph
   joints at most ``path_ratio`` times the net change's L1 norm, so not a nod or a sway).

Every excerpt must stay within ``pose_max_deg`` of the clip's median pose on every graph
joint (smoothed), so that a held bow or a look at the floor is not a listener's rest. Each
excerpt keeps its frames (both end frames included: a cut point is shared) of the graph
joints, unsmoothed; its duration is ``(n - 1) / fps``.

**Cut points** (:class:`ListenerGraph`, after MIMiC's subsequences joined at near poses,
thesis §4.3.1): the distance from the end of excerpt ``a`` to the start of excerpt ``b`` is the
L2 norm of the pose difference and of the velocity difference times ``vel_weight_s`` (rad;
velocities from the first/last frame differences), the pose + velocity test that MIMiC's
transitions use (:mod:`gesture_sim.control.mimic` compares poses and first movements in its PCA
space; here the space is the graph joints themselves, a few angles with one unit).
``cut_dist`` holds them all; ``a -> b`` is an edge of the graph when the distance is at most
``theta_deg``. At run time (:meth:`ListenerGraph.choose`) a state's excerpt is drawn by roulette
among that state's excerpts with weight ``exp(-d^2 / (2 theta^2))``, ``d`` the distance from the
listener's current pose and velocity to the excerpt's start (from an excerpt's end this is the
graph's edge weight); the remaining mismatch is blended out (the player's business:
:class:`~gesture_sim.signals.listener_audio.AudioListener`).

:func:`default_listener_graph` gives the shipped library's graph: read from
``listener_graph.npz`` next to the library when it is there and names the library's
fingerprint (``tools/listener_frames.py --write-cache`` writes it), else extracted from the
library (cached per process). On the shipped library (fingerprint ``47ab34f193f218d9``) the
default settings find 28 rests, 27 nods and 7 posture shifts (243 cut points within θ);
reading the stored graph takes about 15 ms, extracting it about 0.2 s after the library's own
0.4-0.5 s load (2 shared cores).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from gesture_sim.errors import GestureSimError

__all__ = ["ARM_JOINTS", "CACHE_FILE", "GRAPH_JOINTS", "KINDS", "Excerpt", "ExtractSettings",
           "ListenerGraph", "default_listener_graph", "extract_excerpts", "listener_graph_for",
           "still_mask"]

#: The listener's body joints the graph drives (a subset of ``LISTENER_JOINTS``, same order).
GRAPH_JOINTS: tuple[str, ...] = (
    "neck_flex", "neck_bend", "neck_twist", "head_flex", "head_bend", "head_twist",
    "lower_spine_flex", "lower_spine_bend", "upper_spine_bend",
)
#: Arm joints that must be nearly still in a rest excerpt.
ARM_JOINTS: tuple[str, ...] = tuple(
    f"{s}_{j}" for s in ("left", "right")
    for j in ("shoulder_flex", "shoulder_abduct", "shoulder_twist", "elbow_flex"))
#: Excerpt kinds, the listener states.
KINDS: tuple[str, ...] = ("rest", "nod", "posture")
#: File name of the stored graph next to its library.
CACHE_FILE = "listener_graph.npz"
_FORMAT = "gesture_sim.listener_graph/1"
_G = {n: i for i, n in enumerate(GRAPH_JOINTS)}
_SPINE = ("lower_spine_flex", "lower_spine_bend", "upper_spine_bend")


@dataclass(frozen=True)
class ExtractSettings:
    """Thresholds of :func:`extract_excerpts` (module docstring; deg, deg/s, s)."""

    smooth_s: float = 0.1
    pose_max_deg: float = 8.0
    rest_s: float = 0.5
    rest_range_deg: float = 1.2
    rest_arm_range_deg: float = 4.0
    nod_min_deg: float = 3.0
    nod_max_deg: float = 15.0
    return_frac: float = 0.5
    nod_min_s: float = 0.3
    nod_max_s: float = 1.2
    turn_dps: float = 3.0
    side_frac: float = 1.0
    side_deg: float = 1.0
    nod_spine_deg: float = 5.0
    nod_speed_dps: float = 100.0
    rough_frac: float = 0.1
    still_s: float = 0.3
    still_range_deg: float = 0.6
    gap_min_s: float = 0.4
    gap_max_s: float = 4.0
    shift_min_deg: float = 1.5
    shift_max_deg: float = 10.0
    shift_share: float = 0.5
    shift_speed_dps: float = 30.0
    path_ratio: float = 3.0
    vel_weight_s: float = 0.1
    theta_deg: float = 2.0


@dataclass
class Excerpt:
    """One excerpt of real frames.

    Attributes:
        kind: ``"rest"``, ``"nod"`` or ``"posture"``. clip: its clip's name.
        start, end: first and last frame in the clip (both included).
        frames: (end - start + 1, len(GRAPH_JOINTS)) rad, relative to the clip's median pose.
        peak: frame (from ``start``) of the nod's lowest head, or of the shift's fastest
            change; the middle frame of a rest.
    """

    kind: str
    clip: str
    start: int
    end: int
    frames: np.ndarray
    peak: int

    @property
    def n_frames(self) -> int:
        return int(len(self.frames))


# ---------------------------------------------------------------------------- extraction

def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average of ``n`` (odd) frames along axis 0, edges padded."""
    if n <= 1 or len(x) < 2:
        return np.asarray(x, float)
    h = n // 2
    xp = np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])
    c = np.cumsum(np.concatenate([np.zeros((1,) + x.shape[1:]), xp]), axis=0)
    return (c[n:] - c[:-n]) / n


def _odd(n: float) -> int:
    k = max(int(round(n)), 1)
    return k if k % 2 else k + 1


def _window_range(x: np.ndarray, w: int) -> np.ndarray:
    """(T,) the largest per-column range of ``x`` (T, d) over the ``w``-frame window centred
    on each frame (edges padded with the end frames)."""
    if not x.shape[1] or not len(x):
        return np.zeros(len(x))
    h = w // 2
    xp = np.concatenate([np.repeat(x[:1], h, 0), x, np.repeat(x[-1:], h, 0)])
    win = np.lib.stride_tricks.sliding_window_view(xp, w, axis=0)     # (T, d, w)
    return (win.max(axis=2) - win.min(axis=2)).max(axis=1)


def still_mask(x: np.ndarray, fps: float, window_s: float, range_rad: float) -> np.ndarray:
    """(T,) bool: every column of ``x`` (T, d) ranges at most ``range_rad`` over the
    ``window_s`` window centred on the frame."""
    if not len(x):
        return np.zeros(0, bool)
    return _window_range(np.asarray(x, float), _odd(window_s * fps)) <= range_rad + 1e-12


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(first, last)] of the True runs of ``mask`` (both included)."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    d = np.diff(m.astype(int))
    return list(zip(np.flatnonzero(d == 1).tolist(), (np.flatnonzero(d == -1) - 1).tolist(),
                    strict=True))


def _rests(g: np.ndarray, arms: np.ndarray, fps: float, st: ExtractSettings
           ) -> list[tuple[int, int, int]]:
    d = math.radians
    still = still_mask(g, fps, st.rest_s, d(st.rest_range_deg))
    if arms.shape[1]:
        still &= still_mask(arms, fps, st.rest_s, d(st.rest_arm_range_deg))
    piece = max(int(round(st.rest_s * fps)), 1)
    out = []
    for a, b in _runs(still):
        s = a
        while s + piece <= b:
            out.append((s, s + piece, piece // 2))
            s += piece
    return out


def _nods(g: np.ndarray, gs: np.ndarray, fps: float, st: ExtractSettings
          ) -> list[tuple[int, int, int]]:
    d = math.radians
    p = gs[:, _G["neck_flex"]] + gs[:, _G["head_flex"]]
    p_raw = g[:, _G["neck_flex"]] + g[:, _G["head_flex"]]
    roll = gs[:, _G["neck_bend"]] + gs[:, _G["head_bend"]]
    yaw = gs[:, _G["neck_twist"]] + gs[:, _G["head_twist"]]
    spine = gs[:, [_G[n] for n in _SPINE]]
    if len(p) < 3:
        return []
    peaks = np.flatnonzero((p[1:-1] > p[:-2]) & (p[1:-1] >= p[2:])) + 1    # local maxima
    turn = d(st.turn_dps) / fps
    lim = int(math.ceil(st.nod_max_s * fps))
    out: list[tuple[int, int, int]] = []
    for i in peaks.tolist():
        s = i
        while s > 0 and i - s < lim and p[s - 1] < p[s]:
            s -= 1
        while s < i and p[s + 1] - p[s] < turn:      # the slow tail before the descent
            s += 1
        e = i
        while e < len(p) - 1 and e - i < lim and p[e + 1] < p[e] and p[e] > p[s]:
            e += 1
        while e > i and p[e - 1] - p[e] < turn:
            e -= 1
        down, up = p[i] - p[s], p[i] - p[e]
        dur = (e - s) / fps
        if not (d(st.nod_min_deg) <= down <= d(st.nod_max_deg)):
            continue
        if not (st.return_frac * down <= up <= down / st.return_frac):
            continue
        if not (st.nod_min_s <= dur <= st.nod_max_s):
            continue
        side = st.side_frac * down + d(st.side_deg)
        if np.ptp(roll[s:e + 1]) > side or np.ptp(yaw[s:e + 1]) > side:
            continue
        if np.max(np.ptp(spine[s:e + 1], axis=0)) > d(st.nod_spine_deg):
            continue
        if np.max(np.abs(np.diff(p[s:e + 1]))) * fps > d(st.nod_speed_dps):
            continue
        if math.sqrt(float(np.mean((p_raw[s:e + 1] - p[s:e + 1]) ** 2))) > st.rough_frac * down:
            continue
        if out and s < out[-1][1]:
            continue
        out.append((s, e, i - s))
    return out


def _postures(gs: np.ndarray, fps: float, st: ExtractSettings) -> list[tuple[int, int, int]]:
    d = math.radians
    still = still_mask(gs, fps, st.still_s, d(st.still_range_deg))
    runs = _runs(still)
    out = []
    for (_, a1), (b0, _) in zip(runs[:-1], runs[1:], strict=True):
        gap = (b0 - a1) / fps
        if not (st.gap_min_s <= gap <= st.gap_max_s):
            continue
        seg = gs[a1:b0 + 1]
        net = seg[-1] - seg[0]
        lean = net[_G["lower_spine_flex"]]
        bend = net[_G["lower_spine_bend"]] + net[_G["upper_spine_bend"]]
        tilt = net[_G["neck_bend"]] + net[_G["head_bend"]]
        pitch = net[_G["neck_flex"]] + net[_G["head_flex"]]
        yaw = net[_G["neck_twist"]] + net[_G["head_twist"]]
        m = math.sqrt(lean * lean + bend * bend + tilt * tilt)
        total = math.sqrt(m * m + pitch * pitch + yaw * yaw)
        if not (d(st.shift_min_deg) <= m and total <= d(st.shift_max_deg)):
            continue
        if m < st.shift_share * total:
            continue
        vel = np.abs(np.diff(seg, axis=0)) * fps
        if vel.max() > d(st.shift_speed_dps):
            continue
        if vel.sum() / fps > st.path_ratio * float(np.abs(net).sum()):
            continue
        out.append((a1, b0, int(np.argmax(vel.max(axis=1)))))
    return out


def extract_excerpts(qpos: np.ndarray, joint_names, fps: float, clip: str = "",
                     settings: ExtractSettings | None = None) -> list[Excerpt]:
    """The rest, nod and posture excerpts of one clip (module docstring), in that order and
    in time order within each kind.

    Args:
        qpos: (T, n_joints) joint angles (rad) over ``joint_names``; graph or arm joints the
            clip lacks count as still at 0.
        fps: frame rate (Hz). clip: the clip's name (recorded).

    Returns:
        The excerpts, frames relative to the clip's median pose of :data:`GRAPH_JOINTS`.
    """
    st = settings or ExtractSettings()
    q = np.asarray(qpos, float)
    idx = {n: i for i, n in enumerate(joint_names)}

    def cols(names) -> np.ndarray:
        return np.column_stack([q[:, idx[n]] if n in idx else np.zeros(len(q))
                                for n in names]) if len(q) else np.zeros((0, len(names)))

    g = cols(GRAPH_JOINTS)
    if len(g) < 3:
        return []
    arms = cols([n for n in ARM_JOINTS if n in idx]) if any(n in idx for n in ARM_JOINTS) \
        else np.zeros((len(q), 0))
    g = g - np.median(g, axis=0)
    n_s = _odd(st.smooth_s * fps)
    gs = _smooth(g, n_s)
    arms_s = _smooth(arms, n_s) if arms.shape[1] else arms
    out: list[Excerpt] = []
    near = math.radians(st.pose_max_deg)
    for kind, found in (("rest", _rests(gs, arms_s, fps, st)), ("nod", _nods(g, gs, fps, st)),
                        ("posture", _postures(gs, fps, st))):
        for s, e, pk in found:
            if np.abs(gs[s:e + 1]).max() > near:       # not the listener's posture (a bow)
                continue
            out.append(Excerpt(kind, clip, int(s), int(e), g[s:e + 1].astype(np.float64),
                               int(pk)))
    return out


# ---------------------------------------------------------------------------- the graph

def _ends(ex: Excerpt, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    f = ex.frames
    v0 = (f[1] - f[0]) * fps if len(f) > 1 else np.zeros(f.shape[1])
    v1 = (f[-1] - f[-2]) * fps if len(f) > 1 else np.zeros(f.shape[1])
    return f[0], v0, f[-1], v1


@dataclass
class ListenerGraph:
    """Excerpts of real listener motion and their cut points (module docstring).

    Attributes:
        fps: frame rate of the frames (Hz). excerpts: the excerpts.
        settings: how they were found. library: the source library's fingerprint ("" if
            none). cut_dist: (n, n) distance (rad) from each excerpt's end to each one's start.
    """

    fps: float
    excerpts: list[Excerpt]
    settings: ExtractSettings = field(default_factory=ExtractSettings)
    library: str = ""
    cut_dist: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        n = len(self.excerpts)
        ends = [_ends(e, self.fps) for e in self.excerpts]
        w = self.settings.vel_weight_s
        self._start_pose = np.array([e[0] for e in ends]).reshape(n, len(GRAPH_JOINTS))
        self._start_vel = np.array([e[1] for e in ends]).reshape(n, len(GRAPH_JOINTS))
        end_pose = np.array([e[2] for e in ends]).reshape(n, len(GRAPH_JOINTS))
        end_vel = np.array([e[3] for e in ends]).reshape(n, len(GRAPH_JOINTS))
        dp = end_pose[:, None, :] - self._start_pose[None, :, :]
        dv = (end_vel[:, None, :] - self._start_vel[None, :, :]) * w
        self.cut_dist = np.sqrt((dp * dp).sum(-1) + (dv * dv).sum(-1))
        self._kind = np.array([KINDS.index(e.kind) for e in self.excerpts], int)

    # ------------------------------------------------------------------ views
    def of_kind(self, kind: str) -> np.ndarray:
        """Indices of the excerpts of ``kind``."""
        return np.flatnonzero(self._kind == KINDS.index(kind))

    def counts(self) -> dict[str, int]:
        """Number of excerpts of each kind."""
        return {k: int(len(self.of_kind(k))) for k in KINDS}

    @property
    def complete(self) -> bool:
        """At least one excerpt of every kind."""
        return all(v > 0 for v in self.counts().values())

    def edges(self) -> np.ndarray:
        """(n, n) bool: ``a -> b`` is a cut point (distance at most ``theta_deg``)."""
        return self.cut_dist <= math.radians(self.settings.theta_deg)

    def start_distance(self, pose: np.ndarray, vel: np.ndarray | None = None) -> np.ndarray:
        """(n,) distance (rad) from ``pose`` (and ``vel``, rad/s; default still) on
        :data:`GRAPH_JOINTS` to every excerpt's start."""
        p = np.asarray(pose, float).reshape(1, -1)
        v = np.zeros_like(p) if vel is None else np.asarray(vel, float).reshape(1, -1)
        dp = self._start_pose - p
        dv = (self._start_vel - v) * self.settings.vel_weight_s
        return np.sqrt((dp * dp).sum(1) + (dv * dv).sum(1))

    def choose(self, kind: str, pose: np.ndarray, vel: np.ndarray | None,
               rng: np.random.Generator) -> int:
        """An excerpt of ``kind`` whose start fits ``pose``/``vel``: roulette (one draw of
        ``rng``) with weights ``exp(-d^2 / (2 theta^2))`` (module docstring).

        Raises:
            GestureSimError: no excerpt of that kind.
        """
        cand = self.of_kind(kind)
        if not len(cand):
            raise GestureSimError(f"the listener graph has no {kind} excerpt")
        d = self.start_distance(pose, vel)[cand]
        th = math.radians(self.settings.theta_deg)
        logw = -0.5 * (d / th) ** 2
        w = np.exp(logw - logw.max())
        u = float(rng.random())
        k = int(np.searchsorted(np.cumsum(w), u * w.sum(), side="right"))
        return int(cand[min(k, len(cand) - 1)])

    # ------------------------------------------------------------------ building, storage
    @classmethod
    def from_library(cls, library, settings: ExtractSettings | None = None) -> ListenerGraph:
        """The excerpts of every clip of a :class:`~gesture_sim.motion.library.MotionLibrary`
        (clips in order)."""
        st = settings or ExtractSettings()
        ex: list[Excerpt] = []
        for c in library.clips:
            ex += extract_excerpts(c.qpos, library.joint_names, library.fps, c.name, st)
        return cls(float(library.fps), ex, st, str(getattr(library, "fingerprint", "")))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write as npz (frames float32 concatenated, an index table and JSON meta)."""
        ex = self.excerpts
        frames = (np.concatenate([e.frames for e in ex]).astype(np.float32) if ex
                  else np.zeros((0, len(GRAPH_JOINTS)), np.float32))
        table = np.array([(KINDS.index(e.kind), e.start, e.end, e.peak, e.n_frames)
                          for e in ex], np.int32).reshape(-1, 5)
        meta = {"format": _FORMAT, "fps": self.fps, "library": self.library,
                "joints": list(GRAPH_JOINTS), "settings": asdict(self.settings),
                "clips": [e.clip for e in ex]}
        try:
            with open(path, "wb") as fh:
                np.savez_compressed(fh, frames=frames, table=table,
                                    meta=np.array(json.dumps(meta)))
        except OSError as exc:
            raise GestureSimError(f"cannot write listener graph {path}: {exc}") from None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ListenerGraph:
        """Read :meth:`save`'s npz.

        Raises:
            GestureSimError: unreadable, another format or other joints.
        """
        try:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                frames = np.asarray(z["frames"], float)
                table = np.asarray(z["table"], int)
            if meta.get("format") != _FORMAT or tuple(meta["joints"]) != GRAPH_JOINTS:
                raise ValueError("not a listener graph of these joints")
            st = ExtractSettings(**meta["settings"])
            ex, k = [], 0
            for (kind, s, e, pk, n), clip in zip(table.tolist(), meta["clips"], strict=True):
                ex.append(Excerpt(KINDS[kind], clip, s, e, frames[k:k + n], pk))
                k += n
            return cls(float(meta["fps"]), ex, st, str(meta.get("library", "")))
        except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
            raise GestureSimError(f"cannot read listener graph {path}: {exc}") from None


_DEFAULT: dict[str, ListenerGraph] = {}


def default_listener_graph(library_dir: str | os.PathLike[str] | None = None) -> ListenerGraph:
    """The listener graph of a library folder (default: the shipped
    ``motion_library/default``): its ``listener_graph.npz`` when that names the library's
    fingerprint and the default settings, else extracted from the library; cached per process
    and folder."""
    if library_dir is None:
        from gesture_sim import DEFAULT_LIBRARY_DIR

        library_dir = DEFAULT_LIBRARY_DIR
    key = str(Path(library_dir).resolve())
    if key in _DEFAULT:
        return _DEFAULT[key]
    graph = None
    cache = Path(library_dir) / CACHE_FILE
    try:
        fp = json.loads((Path(library_dir) / "manifest.json").read_text(encoding="utf-8")
                        ).get("fingerprint")
    except (OSError, ValueError):
        fp = None
    if fp and cache.is_file():
        try:
            g = ListenerGraph.load(cache)
            if g.library == fp and g.settings == ExtractSettings():
                graph = g
        except GestureSimError:
            graph = None
    if graph is None:
        from gesture_sim.motion.library import MotionLibrary

        graph = ListenerGraph.from_library(MotionLibrary.load(library_dir))
    _DEFAULT[key] = graph
    return graph


_BY_FINGERPRINT: dict[str, ListenerGraph] = {}


def listener_graph_for(library) -> ListenerGraph:
    """The listener graph of a loaded :class:`~gesture_sim.motion.library.MotionLibrary`: the
    shipped library's stored graph when the fingerprints match, else extracted from the
    library's own clips (about 0.2 s; cached per process and fingerprint)."""
    fp = str(getattr(library, "fingerprint", "") or "")
    if fp and fp in _BY_FINGERPRINT:
        return _BY_FINGERPRINT[fp]
    try:
        graph = default_listener_graph()
    except GestureSimError:
        graph = None
    if graph is None or not fp or graph.library != fp:
        graph = ListenerGraph.from_library(library)
    if fp:
        _BY_FINGERPRINT[fp] = graph
    return graph
