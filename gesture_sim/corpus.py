"""Training a whole stack — motion library, inference model, controller policy — from a corpus
folder (``gesture-sim train --corpus DIR -o MODEL_DIR``).

Layouts (:func:`discover`):

* **BEAT2**: ``DIR/smplxflame_30/<stem>.npz`` (SMPL-X motion), ``DIR/wave16k/<stem>.wav``
  (speech) and, optional, ``DIR/textgrid/<stem>.TextGrid`` (word alignment), paired by file
  stem. A BEAT2 stem ``2_scott_0_1_1`` is speaker id ``2``, speaker ``scott``. Chosen when
  ``DIR/smplxflame_30`` is a folder.
* **Folder** (ZEGGS style): every ``.bvh`` or SMPL-X ``.npz`` motion file under ``DIR``
  (recursively; hidden folders and the run's own output and cache folders are left out) with a
  ``.wav`` of the same stem beside it, and optionally a ``.TextGrid`` of the same stem. The
  speaker of a file is the name of its top-level subfolder of ``DIR`` (the name of ``DIR``
  itself for files directly in it).

Only pairs are used: a motion file without its speech is reported (``unpaired``) and left out
of both the library and the model, so the library holds exactly the motion the model was trained
on. Pairs are ordered by name (BEAT2: stem; folder: path relative to ``DIR``), so the result
does not depend on the order in which the per-file work finishes.

Per pair, one analysis (:func:`analyse_pair`): the motion file is read **once**, resampled to
the library rate, retargeted, segmented and parametrised
(:func:`gesture_sim.motion.build.analyse_clip`); the same analysis gives the library clip and
the inference training take (:func:`gesture_sim.inference.train.motion_take_from_analysis`).
The speech goes through the causal prosody tracker; the TextGrid's words are read when there is
one (counted in the summary; training does not use them). Each analysis is stored in the cache
folder as one ``.npz`` written atomically, named by a sha256 of the files' bytes and of the
settings that affect it (:func:`cache_key`), so an interrupted run resumes where it stopped and
gives the same result as an uninterrupted one. Every result, fresh or cached, is read back from
its cache file, so a fresh and a resumed run train on bit-identical inputs.

Then over all pairs: the library is assembled (normalisation fitted on its clips), the
inference model is trained with that normalisation (:func:`~gesture_sim.inference.train.
train_model`), the controller policy is solved for the two
(:func:`~gesture_sim.loading.train_library_policy`), and the folder is written atomically
(:func:`write_stack`): ``library.npz``, ``manifest.json``, ``model/model.json``,
``model/model.npz``, ``model/policy.npz`` and ``README.md`` — the layout of
``motion_library/default``, which ``--library MODEL_DIR`` loads (its ``model/`` subfolder).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from gesture_sim.errors import GestureSimError

__all__ = ["CACHE_FORMAT", "Corpus", "CorpusItem", "AnalysisSettings", "PairAnalysis", "Task",
           "analyse_pair", "cache_key", "discover", "load_entry", "no_pairs_message",
           "select_speaker", "train_corpus"]

#: Version of the cache entries' format; part of every cache key.
CACHE_FORMAT = 3
#: Motion file suffixes read (lower case).
MOTION_SUFFIXES = (".bvh", ".npz")
#: BEAT2 layout: sub-folders of the corpus folder.
BEAT2_MOTION, BEAT2_AUDIO, BEAT2_TEXTGRID = "smplxflame_30", "wave16k", "textgrid"
_BEAT2_STEM = re.compile(r"^(?P<id>\d+)_(?P<name>[A-Za-z]+)_")
#: The README written beside the library.
README = "README.md"


# --------------------------------------------------------------------------------------------
# Discovery
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CorpusItem:
    """One motion + speech pair of a corpus.

    Attributes:
        name: the clip name (the stem; for a folder corpus whose stems repeat across folders,
            the path relative to the corpus with ``/`` as ``_``).
        motion, audio: the files. textgrid: the word alignment, or None.
        speaker: the speaker (see the module docstring).
    """

    name: str
    motion: Path
    audio: Path
    textgrid: Path | None
    speaker: str


@dataclass
class Corpus:
    """What :func:`discover` found: ``items`` (pairs, ordered by name), ``unpaired`` (motion
    files without speech) and the ``layout`` (``"beat2"`` or ``"folder"``)."""

    root: Path
    layout: str
    items: list[CorpusItem]
    unpaired: list[Path] = field(default_factory=list)
    unpaired_speakers: list[str] = field(default_factory=list)

    def speakers(self) -> dict[str, dict[str, int]]:
        """speaker -> {"pairs": n, "unpaired": m}, sorted by speaker."""
        out: dict[str, dict[str, int]] = {}
        for it in self.items:
            out.setdefault(it.speaker, {"pairs": 0, "unpaired": 0})["pairs"] += 1
        for sp in self.unpaired_speakers:
            out.setdefault(sp, {"pairs": 0, "unpaired": 0})["unpaired"] += 1
        return dict(sorted(out.items()))

    def files(self) -> list[Path]:
        """Every input file of the pairs (motion, audio, TextGrid)."""
        return [f for it in self.items for f in (it.motion, it.audio, it.textgrid)
                if f is not None]


def beat2_speaker(stem: str) -> tuple[str, str] | None:
    """(speaker id, speaker name) of a BEAT2 stem such as ``2_scott_0_1_1``; None otherwise."""
    m = _BEAT2_STEM.match(stem)
    return (m["id"], m["name"].lower()) if m else None


def _by_lower(folder: Path, suffix: str) -> dict[str, Path]:
    """stem -> file of ``folder``'s regular files with ``suffix`` (any case)."""
    out: dict[str, Path] = {}
    try:
        entries = sorted(folder.iterdir())
    except OSError:
        return out
    for p in entries:
        if p.suffix.lower() == suffix.lower() and p.is_file():
            out.setdefault(p.stem, p)
    return out


def discover(root: str | os.PathLike[str], exclude: Sequence[str | os.PathLike[str]] = ()
             ) -> Corpus:
    """The pairs of a corpus folder (layouts: see the module docstring); ``exclude``: folders
    to leave out of a folder corpus (the run's output and cache).

    Raises:
        GestureSimError: ``root`` is not a readable folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise GestureSimError(f"--corpus {root}: no such folder")
    if (root / BEAT2_MOTION).is_dir():
        return _discover_beat2(root)
    return _discover_folder(root, exclude)


def _discover_beat2(root: Path) -> Corpus:
    motions = _by_lower(root / BEAT2_MOTION, ".npz")
    audios = _by_lower(root / BEAT2_AUDIO, ".wav")
    grids = _by_lower(root / BEAT2_TEXTGRID, ".textgrid")
    items, unpaired, unpaired_sp = [], [], []
    for stem in sorted(motions):
        sp = beat2_speaker(stem)
        speaker = sp[1] if sp else "unknown"
        if stem in audios:
            items.append(CorpusItem(stem, motions[stem], audios[stem], grids.get(stem), speaker))
        else:
            unpaired.append(motions[stem])
            unpaired_sp.append(speaker)
    return Corpus(root, "beat2", items, unpaired, unpaired_sp)


def _discover_folder(root: Path, exclude: Sequence[str | os.PathLike[str]]) -> Corpus:
    skip = {Path(os.path.abspath(e)) for e in exclude}
    found: list[tuple[str, Path, Path | None, Path | None, str]] = []
    unpaired, unpaired_sp = [], []
    for folder, dirs, _files in os.walk(root):
        here = Path(folder)
        dirs[:] = sorted(d for d in dirs if not d.startswith(".")
                         and Path(os.path.abspath(here / d)) not in skip)
        rel_dir = here.relative_to(root)
        speaker = rel_dir.parts[0] if rel_dir.parts else root.resolve().name
        audios = _by_lower(here, ".wav")
        grids = _by_lower(here, ".textgrid")
        for suffix in MOTION_SUFFIXES:
            for stem, motion in _by_lower(here, suffix).items():
                rel = motion.relative_to(root).as_posix()
                if stem in audios:
                    found.append((rel, motion, audios[stem], grids.get(stem), speaker))
                else:
                    unpaired.append(motion)
                    unpaired_sp.append(speaker)
    found.sort(key=lambda f: f[0])
    stems = [f[1].stem for f in found]
    items = []
    for (rel, motion, audio, grid, speaker), stem in zip(found, stems, strict=True):
        name = stem if stems.count(stem) == 1 else rel.rsplit(".", 1)[0].replace("/", "_")
        items.append(CorpusItem(name, motion, audio, grid, speaker))
    order = sorted(range(len(unpaired)), key=lambda i: unpaired[i].as_posix())
    return Corpus(root, "folder", items, [unpaired[i] for i in order],
                  [unpaired_sp[i] for i in order])


def select_speaker(corpus: Corpus, speaker: str) -> Corpus:
    """The pairs of one speaker: matched without regard to case against the speaker name, and
    for BEAT2 stems also against the speaker id (``2``) and ``id_name`` (``2_scott``).

    Raises:
        GestureSimError: no pair of that speaker (the speakers found are listed).
    """
    want = speaker.strip().lower()

    def match(name: str, path: Path) -> bool:
        if name.lower() == want:
            return True
        sp = beat2_speaker(path.stem) if corpus.layout == "beat2" else None
        return sp is not None and want in (sp[0], f"{sp[0]}_{sp[1]}")

    items = [it for it in corpus.items if match(it.speaker, it.motion)]
    if not items:
        have = ", ".join(f"{k} ({v['pairs']} pairs)" for k, v in corpus.speakers().items())
        raise GestureSimError(f"--speaker {speaker}: no pair of that speaker in {corpus.root} "
                              f"(speakers: {have or 'none'})")
    keep = [i for i, p in enumerate(corpus.unpaired) if match(corpus.unpaired_speakers[i], p)]
    return Corpus(corpus.root, corpus.layout, items, [corpus.unpaired[i] for i in keep],
                  [corpus.unpaired_speakers[i] for i in keep])


# --------------------------------------------------------------------------------------------
# Per-pair analysis and its cache
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AnalysisSettings:
    """What the per-pair analysis depends on besides the files (part of the cache key).

    Attributes:
        fps: the library frame rate (Hz); motion at another rate is resampled.
        segmentation: the segmentation thresholds (``SegmentationSettings.to_dict()``;
            defaults when None).
        tag_rules: clip-name pattern -> tags (the Bandai Namco defaults when None).
        licence: the licence of every input (guessed from known dataset names when None).
    """

    fps: float = 30.0
    segmentation: dict | None = None
    tag_rules: dict[str, list[str]] | None = None
    licence: str | None = None

    def segmentation_settings(self) -> Any:
        from gesture_sim.motion.segmentation import SegmentationSettings

        return SegmentationSettings(**self.segmentation) if self.segmentation else \
            SegmentationSettings()

    def key_dict(self) -> dict:
        """Everything the analysis depends on besides the files' bytes and names."""
        from gesture_sim import __version__
        from gesture_sim.audio.prosody import ProsodyConfig
        from gesture_sim.motion.build import DEFAULT_TAG_RULES

        return {"format": CACHE_FORMAT, "version": __version__, "fps": float(self.fps),
                "segmentation": self.segmentation_settings().to_dict(),
                "tag_rules": DEFAULT_TAG_RULES if self.tag_rules is None else self.tag_rules,
                "licence": self.licence, "prosody": asdict(ProsodyConfig())}


def file_digest(path: str | os.PathLike[str]) -> str:
    """sha256 (hex) of a file's bytes."""
    try:
        with open(path, "rb") as fh:
            return hashlib.file_digest(fh, "sha256").hexdigest()
    except OSError as exc:
        raise GestureSimError(f"{path}: cannot read ({exc.strerror})") from None


def cache_key(item: CorpusItem, settings: AnalysisSettings) -> str:
    """24 hex digits of sha256 over the pair's file contents (motion, speech, TextGrid), its
    clip name and motion file name, and :meth:`AnalysisSettings.key_dict` (which includes
    :data:`CACHE_FORMAT` and the package version). Size and modification time are not used:
    a file rewritten with other bytes gets another key, a copy of the same bytes the same."""
    h = hashlib.sha256(json.dumps(settings.key_dict(), sort_keys=True).encode())
    h.update(json.dumps([item.name, item.motion.name, item.motion.suffix.lower()]).encode())
    for f in (item.motion, item.audio, item.textgrid):
        h.update(b"\0" + (file_digest(f).encode() if f is not None else b"none"))
    return h.hexdigest()[:24]


def cache_file(cache_dir: str | os.PathLike[str], item: CorpusItem, key: str) -> Path:
    """Where the analysis of ``item`` with ``key`` is cached."""
    safe = re.sub(r"[^\w.-]", "_", item.name)[:80]
    return Path(cache_dir) / f"{safe}.{key}.npz"


@dataclass
class PairAnalysis:
    """One pair, analysed (read back from its cache file).

    Attributes:
        clip: the :class:`~gesture_sim.motion.build.ClipAnalysis` of the motion.
        syllables: the speech's syllables (:class:`~gesture_sim.contracts.Syllable`).
        audio_duration_s: length of the speech (s).
        words: (start s, end s, word) of the TextGrid's word tier that start within the
            speech (empty without a TextGrid).
        name: the clip name.
    """

    clip: Any
    syllables: list
    audio_duration_s: float
    words: list[tuple[float, float, str]]
    name: str

    def training_take(self) -> Any:
        """The inference layer's :class:`~gesture_sim.inference.train.TrainingTake`."""
        from gesture_sim.inference.train import TrainingTake, motion_take_from_analysis

        return TrainingTake(motion_take_from_analysis(self.clip), list(self.syllables),
                            self.audio_duration_s, name=self.name)


_RETARGETER: Any = None


def _retargeter() -> Any:
    """One retargeter per process (loading the humanoid takes a moment)."""
    global _RETARGETER
    if _RETARGETER is None:
        from gesture_sim.motion.retarget import Retargeter

        _RETARGETER = Retargeter()
    return _RETARGETER


def _words(path: Path) -> list[tuple[float, float, str]]:
    from gesture_sim.audio.textgrid import read_textgrid

    grid = read_textgrid(path)
    tier = next((grid[k] for k in grid if k.lower() in ("words", "word")), None)
    if tier is None:
        tier = next(iter(grid.values()), [])
    return [(float(iv.xmin), float(iv.xmax), iv.text.strip()) for iv in tier
            if iv.text.strip()]


def check_textgrid_times(textgrid: str | os.PathLike[str], audio: str | os.PathLike[str],
                         audio_s: float | None = None) -> None:
    """A pair's TextGrid must fit its speech: no labelled time before 0 s or past the audio's
    end by more than :data:`~gesture_sim.validation.SIDE_FILE_OVERRUN_S` (a 64 s alignment
    beside 10 s of audio belongs to another recording). ``audio_s``: the audio's length (s),
    read from its header when None.

    Raises:
        GestureSimError: one line naming the TextGrid, the time and the audio.
    """
    from gesture_sim.audio.sources import audio_duration_s
    from gesture_sim.audio.textgrid import read_textgrid, timed_items
    from gesture_sim.validation import side_file_times

    items = timed_items(read_textgrid(textgrid))
    if items:
        length = audio_duration_s(audio) if audio_s is None else audio_s
        side_file_times("", textgrid, items, length, f"its audio {Path(audio).name}",
                        "is the TextGrid for this recording?")


def analyse_pair(motion: str, audio: str, textgrid: str | None, name: str, settings: dict,
                 target: str) -> dict:
    """Analyse one pair and store it at ``target`` (atomically); the per-file job of
    :func:`train_corpus`, run in this process, a worker process or a Dask worker.

    ``settings``: :class:`AnalysisSettings` as a dict. Returns ``{"cache": target, "seconds",
    "segments"}``.

    Raises:
        GestureSimError: a file that cannot be read, a motion too short or too still to
            segment, or motion and speech durations that differ by more than 10 % (and 1 s);
            the message names the file.
    """
    from gesture_sim.audio.prosody import analyze_file
    from gesture_sim.contracts import SAMPLE_RATE
    from gesture_sim.inference.train import check_pair_duration, motion_take_from_analysis
    from gesture_sim.motion.build import analyse_clip

    cfg = AnalysisSettings(**settings)

    def named(exc: GestureSimError, path: str) -> GestureSimError:
        text = str(exc)
        return exc if (motion in text or audio in text or (textgrid and textgrid in text)) \
            else GestureSimError(f"{path}: {text}")

    try:
        clip = analyse_clip(motion, cfg.tag_rules, fps=cfg.fps,
                            settings=cfg.segmentation_settings(), licence=cfg.licence,
                            retargeter=_retargeter())
        motion_take_from_analysis(clip, motion)          # at least two segments
    except GestureSimError as exc:
        raise named(exc, motion) from None
    if clip.clip.name != name:
        clip = replace(clip, clip=replace(clip.clip, name=name),
                       report=replace(clip.report, name=name))
    try:
        prosody = analyze_file(audio)
    except GestureSimError as exc:
        raise named(exc, audio) from None
    audio_s = len(prosody.samples) / SAMPLE_RATE
    motion_s = clip.clip.n_frames / clip.clip.fps
    check_pair_duration(motion_s, audio_s, f"{motion} + {audio}")
    words: list[tuple[float, float, str]] = []
    if textgrid is not None:
        try:
            check_textgrid_times(textgrid, audio, audio_s)
            words = [w for w in _words(Path(textgrid)) if w[0] < audio_s]  # within the take
        except GestureSimError as exc:
            raise named(exc, textgrid) from None
    _save_entry(Path(target), clip, prosody.syllables, audio_s, words, name)
    return {"cache": target, "seconds": motion_s, "segments": len(clip.segments)}


def _save_entry(path: Path, clip: Any, syllables: Sequence, audio_s: float,
                words: list[tuple[float, float, str]], name: str) -> None:
    from gesture_sim.fileio import atomic_path

    c, r = clip.clip, clip.report
    syl = np.array([[s.t_start, s.t_end, s.t_emitted, np.nan if s.f0_hz is None else s.f0_hz,
                     s.intensity_db, float(bool(s.voiced))] for s in syllables],
                   dtype=np.float64).reshape(-1, 6)
    meta = {
        "format": CACHE_FORMAT, "name": name, "audio_duration_s": float(audio_s),
        "clip": {"name": c.name, "fps": float(c.fps), "source": c.source, "licence": c.licence,
                 "tags": list(c.tags), "retarget_error": float(c.retarget_error)},
        "report": {"name": r.name, "family": r.family, "frames": int(r.frames),
                   "seconds": float(r.seconds), "segments": int(r.segments),
                   "retarget_error": float(r.retarget_error),
                   "retarget_error_p95": float(r.retarget_error_p95)},
        "joint_names": list(clip.joint_names), "words": [w[2] for w in words],
    }
    arrays = {"qpos": c.qpos, "root_pos": c.root_pos, "root_quat": c.root_quat,
              "keypoints": c.keypoints, "segments": np.asarray(clip.segments, dtype=np.int64),
              "raw": np.asarray(clip.raw, dtype=np.float64), "syllables": syl,
              "word_times": np.array([[w[0], w[1]] for w in words],
                                     dtype=np.float64).reshape(-1, 2),
              "meta": np.array(json.dumps(meta))}
    if clip.fingers is not None:
        arrays["fingers"] = np.asarray(clip.fingers, dtype=np.float32)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)


def load_entry(path: str | os.PathLike[str]) -> PairAnalysis:
    """A cache entry written by :func:`analyse_pair`.

    Raises:
        GestureSimError: the file is missing or does not decode as an entry of this format.
    """
    from gesture_sim.contracts import Syllable
    from gesture_sim.fileio import decoding_exceptions
    from gesture_sim.motion.build import ClipAnalysis, ClipReport
    from gesture_sim.motion.library import Clip

    try:
        with np.load(path, allow_pickle=False) as d:
            a = {k: d[k] for k in d.files}
        meta = json.loads(str(a["meta"]))
        if meta.get("format") != CACHE_FORMAT:
            raise ValueError("another cache format")
        c = meta["clip"]
        clip = Clip(name=c["name"], fps=c["fps"], qpos=a["qpos"], root_pos=a["root_pos"],
                    root_quat=a["root_quat"], source=c["source"], licence=c["licence"],
                    tags=tuple(c["tags"]), keypoints=a["keypoints"],
                    retarget_error=c["retarget_error"])
        analysis = ClipAnalysis(clip, a["segments"].astype(int), a["raw"],
                                ClipReport(**meta["report"]), tuple(meta["joint_names"]),
                                a.get("fingers"))
        syllables = [Syllable(float(s[0]), float(s[1]), float(s[2]),
                              None if np.isnan(s[3]) else float(s[3]), float(s[4]),
                              bool(s[5] > 0.5)) for s in a["syllables"]]
        words = [(float(t[0]), float(t[1]), w)
                 for t, w in zip(a["word_times"], meta["words"], strict=True)]
        return PairAnalysis(analysis, syllables, float(meta["audio_duration_s"]), words,
                            meta["name"])
    except (*decoding_exceptions(), json.JSONDecodeError) as exc:
        raise GestureSimError(f"cache entry {path} does not decode ({exc})") from None


# --------------------------------------------------------------------------------------------
# Running the per-file work
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Task:
    """One per-file job: ``fn(*args)``; ``label`` (the motion file) names it in messages."""

    label: str
    fn: Callable[..., Any]
    args: tuple


#: Runs tasks and gives (value, one-line error or None) per task, in the tasks' order;
#: ``fail_fast``: raise GestureSimError (naming the task) at the first failure.
Runner = Callable[[Sequence[Task], bool], list[tuple[Any, str | None]]]


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if isinstance(exc, GestureSimError):
        return text or "error"
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def _named(label: str, message: str) -> str:
    return message if label in message else f"{label}: {message}"


def serial_runner(show_progress: bool = True) -> Runner:
    """A :data:`Runner` that runs the tasks one after the other in this process, with a bar."""
    from gesture_sim.progress import progress

    def run(tasks: Sequence[Task], fail_fast: bool) -> list[tuple[Any, str | None]]:
        out: list[tuple[Any, str | None]] = []
        for t in progress(list(tasks), desc="analysing files", unit="file",
                          enabled=show_progress):
            try:
                out.append((t.fn(*t.args), None))
            except Exception as exc:  # noqa: BLE001 - one file's failure is data (--on-error)
                line = _named(t.label, _one_line(exc))
                if fail_fast:
                    raise GestureSimError(line) from None
                out.append((None, line))
        return out
    return run


# --------------------------------------------------------------------------------------------
# The whole run
# --------------------------------------------------------------------------------------------


@dataclass
class CorpusRun:
    """What :func:`train_corpus` did: the trained stack and the figures of its summary."""

    library: Any
    reports: list
    model: Any
    policy: Any
    analyses: list[PairAnalysis]
    summary: dict


def train_corpus(
    corpus: Corpus, output: str | os.PathLike[str], cache_dir: str | os.PathLike[str], *,
    train_settings: Any = None, analysis: AnalysisSettings | None = None,
    on_error: str = "stop", runner: Runner | None = None, show_progress: bool = True,
    on_stage: Callable[[str], None] | None = None,
) -> CorpusRun:
    """Analyse every pair of ``corpus`` (cached in ``cache_dir``), train the library, model and
    policy, and write them into ``output`` (see the module docstring).

    Args:
        corpus: the pairs (:func:`discover`, :func:`select_speaker`).
        output: the folder to write (checked by the caller: never an input).
        cache_dir: where the per-pair analyses are kept between runs.
        train_settings: :class:`~gesture_sim.inference.train.TrainSettings` (defaults if None).
        analysis: the per-pair settings (defaults if None).
        on_error: ``"stop"``: the first broken pair raises GestureSimError naming its file;
            ``"skip"``: it is left out and listed in the summary's ``skipped``.
        runner: runs the per-file jobs (:func:`serial_runner` when None; the command line
            passes one over worker processes or Dask).
        show_progress: progress bars on stderr.
        on_stage: called with a short description as each stage after the per-file work
            starts (library, the model's stages, policy, writing).

    Raises:
        GestureSimError: a broken pair with ``on_error="stop"``, no usable pair, too little
            speech to train on, or an output that cannot be written.
    """
    from gesture_sim.inference.train import TrainSettings

    if on_error not in ("stop", "skip"):
        raise GestureSimError(f"--on-error must be stop or skip, not {on_error!r}")
    if not corpus.items:
        raise GestureSimError(no_pairs_message(corpus))
    cfg = train_settings or TrainSettings()
    an = analysis or AnalysisSettings()
    runner = runner or serial_runner(show_progress)
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()

    # per-file work: hits are read back, misses run as jobs and are then read back
    keys = [cache_key(it, an) for it in corpus.items]
    targets = [cache_file(cache_dir, it, k) for it, k in zip(corpus.items, keys, strict=True)]
    loaded: dict[int, PairAnalysis] = {}
    for i, target in enumerate(targets):
        if target.is_file():
            try:
                loaded[i] = load_entry(target)
            except GestureSimError:
                pass                       # a damaged entry is recomputed (and replaced)
    hits = len(loaded)
    pending = [i for i in range(len(corpus.items)) if i not in loaded]
    if on_error == "stop":     # a damaged npz, a TextGrid of another recording: before any work
        from gesture_sim.validation import motion_file

        for i in pending:
            motion_file("--corpus", corpus.items[i].motion)
            if corpus.items[i].textgrid is not None:
                check_textgrid_times(corpus.items[i].textgrid, corpus.items[i].audio)
    settings_dict = asdict(an)
    tasks = [Task(str(corpus.items[i].motion), analyse_pair,
                  (str(corpus.items[i].motion), str(corpus.items[i].audio),
                   None if corpus.items[i].textgrid is None else str(corpus.items[i].textgrid),
                   corpus.items[i].name, settings_dict, str(targets[i]))) for i in pending]
    skipped: list[dict[str, str]] = []
    if tasks:
        Path(cache_dir).mkdir(parents=True, exist_ok=True)
        results = runner(tasks, on_error == "stop")
        for i, (_value, error) in zip(pending, results, strict=True):
            if error is not None:
                skipped.append({"file": str(corpus.items[i].motion), "reason": error})
                continue
            loaded[i] = load_entry(targets[i])
    seconds["analysis"] = time.perf_counter() - t0
    used = [corpus.items[i] for i in sorted(loaded)]
    analyses = [loaded[i] for i in sorted(loaded)]
    if not analyses:
        raise GestureSimError(f"--corpus {corpus.root}: no usable pair; all "
                              f"{len(corpus.items)} were skipped (first: "
                              f"{skipped[0]['reason']})")

    stage_names: list[tuple[str, float]] = []

    def stage(text: str) -> None:
        stage_names.append((text, time.perf_counter()))
        if on_stage is not None:
            on_stage(text)

    stack = _train_stack(analyses, an, cfg, stage, show_progress)
    stage("done")
    for (text, ta), (_n, tb) in zip(stage_names, stage_names[1:], strict=False):
        seconds[re.split(r" \(| among", text)[0]] = tb - ta
    library, reports, model, policy = stack
    summary = _summary(corpus, used, analyses, skipped, library, model, policy, cfg,
                       output, cache_dir, hits, len(pending))
    stage_t = time.perf_counter()
    fingers = {a.clip.clip.name: a.clip.fingers for a in analyses if a.clip.fingers is not None}
    write_stack(output, library, model, policy, readme_text(summary), fingers)
    seconds["write"] = time.perf_counter() - stage_t
    summary["stage_seconds"] = {k: round(v, 3) for k, v in seconds.items()}
    summary["seconds_total"] = round(time.perf_counter() - t0, 3)
    return CorpusRun(library, reports, model, policy, analyses, summary)


def no_pairs_message(corpus: Corpus) -> str:
    """The one line for a corpus without a single motion/speech pair."""
    where = (f"{BEAT2_MOTION}/*.npz with {BEAT2_AUDIO}/<same stem>.wav" if
             corpus.layout == "beat2" else
             "motion files (.bvh, SMPL-X .npz) each with a .wav of the same stem beside it, or "
             f"the BEAT2 layout ({BEAT2_MOTION}/, {BEAT2_AUDIO}/)")
    extra = f"; {len(corpus.unpaired)} motion file(s) have no speech" if corpus.unpaired else ""
    return f"--corpus {corpus.root}: no motion/speech pair found (expected {where}){extra}"


def _train_stack(analyses: list[PairAnalysis], an: AnalysisSettings, cfg: Any,
                 stage: Callable[[str], None], show_progress: bool) -> tuple:
    """(library, reports, model, policy) of the analysed pairs."""
    from gesture_sim.control.inputs import ControlLibrary, StateModel
    from gesture_sim.inference.train import train_model
    from gesture_sim.loading import train_library_policy
    from gesture_sim.motion.build import assemble_library

    stage("library")
    library, reports = assemble_library([a.clip for a in analyses], an.segmentation_settings())
    takes = [a.training_take() for a in analyses]
    model = train_model(takes, cfg, param_normalisation=library.param_normalisation,
                        library_fingerprint=library.fingerprint, on_stage=stage)
    stage("controller policy")
    policy = train_library_policy(ControlLibrary.from_motion_library(library),
                                  StateModel.from_inference(model), show_progress=show_progress)
    return library, reports, model, policy


def write_stack(output: str | os.PathLike[str], library: Any, model: Any, policy: Any,
                readme: str, fingers: dict[str, np.ndarray] | None = None) -> None:
    """Write the library, its finger tracks (``fingers``: clip name -> (T, 40) rad, from the
    SMPL-X hand poses), ``model/`` (model + policy) and the README into ``output``, all
    published together (:func:`gesture_sim.fileio.atomic_folder`), after reading the staged
    files back: the library, the model and the policy must load and fit each other."""
    from gesture_sim.control.inputs import ControlLibrary, StateModel
    from gesture_sim.control.policy import Policy
    from gesture_sim.fileio import atomic_folder
    from gesture_sim.inference.model import GestureModel
    from gesture_sim.loading import POLICY_FILE, check_model_fits_library, is_own_library
    from gesture_sim.motion.library import MotionLibrary

    with atomic_folder(output) as stage:
        library.save(stage)
        if fingers:
            from gesture_sim.motion.finger_tracks import save_finger_tracks

            save_finger_tracks(stage, library, fingers)
        (stage / "model").mkdir()
        model.save(stage / "model")
        policy.save(stage / "model" / POLICY_FILE)
        (stage / README).write_text(readme, encoding="utf-8")
        lib2 = MotionLibrary.load(stage)
        gm2 = GestureModel.load(stage / "model")
        check_model_fits_library(gm2, lib2, Path(output) / "model", Path(output))
        if not is_own_library(gm2, lib2):
            raise GestureSimError("internal error: the trained model does not name its library")
        Policy.load(stage / "model" / POLICY_FILE,
                    ControlLibrary.from_motion_library(lib2).fingerprint,
                    StateModel.from_inference(gm2).fingerprint)


def _summary(corpus: Corpus, used: list[CorpusItem], analyses: list[PairAnalysis],
             skipped: list[dict[str, str]], library: Any, model: Any, policy: Any, cfg: Any,
             output: Any, cache_dir: Any, hits: int, misses: int) -> dict:
    from gesture_sim.control.inputs import StateModel

    s = model.summary
    speakers: dict[str, int] = {}
    for it in used:
        speakers[it.speaker] = speakers.get(it.speaker, 0) + 1
    return {
        "output": str(output), "corpus": str(corpus.root), "layout": corpus.layout,
        "files": len(used),
        "pairs": [{"name": it.name, "motion": str(it.motion), "audio": str(it.audio),
                   "textgrid": None if it.textgrid is None else str(it.textgrid),
                   "speaker": it.speaker, "seconds": round(a.clip.report.seconds, 3),
                   "segments": int(len(a.clip.segments)), "syllables": len(a.syllables),
                   "words": len(a.words), "finger_track": a.clip.fingers is not None}
                  for it, a in zip(used, analyses, strict=True)],
        "skipped": skipped, "unpaired": [str(p) for p in corpus.unpaired],
        "speakers": dict(sorted(speakers.items())),
        "seconds": round(float(library.duration), 3),
        "seconds_of_training_data": s["seconds_of_data"],
        "segments": len(library.segments), "syllables": s["syllables"],
        "words": int(sum(len(a.words) for a in analyses)),
        "states": s["states"], "clusters": s["clusters"], "window": s["window"],
        "rate_hz": float(cfg.steps.rate_hz), "seed": int(cfg.seed),
        "held_out_loglik_per_step": s["held_out_loglik_per_step"],
        "hmm_train_loglik_per_step": s["hmm_train_loglik_per_step"],
        "crf_objective_per_step": s["crf_objective_per_step"],
        "crf_iterations": s["crf_iterations"], "crf_converged": s["crf_converged"],
        "max_retarget_error": round(max(float(a.clip.report.retarget_error)
                                        for a in analyses), 5),
        "licences": sorted({c.licence for c in library.clips}),
        "library_fingerprint": library.fingerprint, "model_fingerprint": model.fingerprint,
        "state_model_fingerprint": StateModel.from_inference(model).fingerprint,
        "policy": {"labels": list(policy.labels[1:]), "tones": list(policy.tones)},
        "cache": {"dir": str(cache_dir), "hits": hits, "misses": misses},
    }


def readme_text(summary: dict) -> str:
    """The README of a trained folder: what it was trained on and the training figures."""
    s = summary
    rows = "\n".join(
        f"| `{p['name']}` | {p['speaker']} | {p['seconds']:.1f} | {p['segments']} | "
        f"{p['syllables']} | {p['words'] if p['textgrid'] else '-'} |" for p in s["pairs"])
    skipped = "\n".join(f"- `{k['file']}`: {k['reason']}" for k in s["skipped"]) or "none"
    unpaired = ("\n".join(f"- `{p}`" for p in s["unpaired"]) or "none")
    speakers = ", ".join(f"{k} ({v} pairs)" for k, v in s["speakers"].items())
    return f"""# A gesture stack trained on a corpus

Written by `gesture-sim train --corpus {s['corpus']}` ({s['layout']} layout): a motion library
(`library.npz`, `manifest.json`), the inference model trained on the same clips with the
library's parameter normalisation (`model/model.json`, `model/model.npz`) and the controller
policy for the two (`model/policy.npz`). Use it with
`gesture-sim render speech.wav --library {s['output']} -o out.mp4`.

## Training data

{s['files']} motion + speech pairs, {s['seconds']:.1f} s of motion
({s['seconds_of_training_data']:.1f} s of training steps where motion and speech overlap),
{s['segments']} segments, {s['syllables']} syllables, {s['words']} aligned words.
Speakers: {speakers}. Licences of the clips: {', '.join(s['licences'])}.

| clip | speaker | seconds | segments | syllables | words |
|---|---|---|---|---|---|
{rows}

Skipped (broken files, `--on-error skip`):
{skipped}

Motion files without speech (not used):
{unpaired}

## Training figures

Remapped CRF over {s['states']} hidden kinematic states, {s['clusters']} prosody clusters,
input window {s['window']} steps at {s['rate_hz']:g} Hz (seed {s['seed']}); CRF objective per
step {s['crf_objective_per_step']:.4f} after {s['crf_iterations']} L-BFGS iterations
(converged: {s['crf_converged']}); HMM training log-likelihood per step
{s['hmm_train_loglik_per_step']:.4f}; largest retarget error
{100 * s['max_retarget_error']:.1f} % of arm length.

Held-out HMM log-likelihood per step by number of states (last 25 % held out; empty when
`--states` was given): `{json.dumps(s['held_out_loglik_per_step'])}`.

Fingerprints: library `{s['library_fingerprint']}`, training data `{s['model_fingerprint']}`,
state model `{s['state_model_fingerprint']}`. Policy labels: {s['policy']['labels'] or 'none'};
tones: {', '.join(s['policy']['tones'])}.

The model holds statistics of the data (Gaussian means/covariances, CRF weights, speaker
normalisation); the library holds the retargeted motion itself, under the licences above.
"""
