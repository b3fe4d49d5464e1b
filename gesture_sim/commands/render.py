"""``gesture-sim render AUDIO -o OUT.mp4``: speech in, a gesturing simulated humanoid out."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from gesture_sim.commands import print_json
from gesture_sim.commands.listener import LISTENER_MOTIONS, check_listener_motion
from gesture_sim.methods import METHODS, REGISTRY, TRANSITIONS
from gesture_sim.sim.looks import DEFAULT_LOOK, LOOKS

if TYPE_CHECKING:
    from gesture_sim.app.batch import DaskTarget


def add_render_options(parser: argparse.ArgumentParser) -> None:
    """Options shared by ``render`` and ``demo``."""
    parser.add_argument("--width", type=int, default=1280, help="frame width in px (default 1280)")
    parser.add_argument("--height", type=int, default=720, help="frame height in px (default 720)")
    parser.add_argument("--fps", type=float, default=30.0, help="video frame rate (default 30)")
    parser.add_argument("--camera", default="front",
                        help="camera: front, side, face, or track (follows the pelvis); for "
                             "a conversation both (the default there), person_0, person_1, "
                             "face_0, face_1")
    parser.add_argument("--library", type=Path, default=None,
                        help="motion library folder (default: the shipped motion_library/default)")
    parser.add_argument("--model", type=Path, default=None,
                        help="inference model folder (default: LIBRARY/model, else the "
                             "shipped model)")
    parser.add_argument("--method", default="controller", choices=METHODS,
                        help="segment selection (default controller): " + "; ".join(
                            f"{spec.name}: {spec.doc}" for spec in REGISTRY.values()))
    parser.add_argument("--sign-model", type=Path, default=None, metavar="DIR",
                        help="with --method chiu14: the sign model folder (signs.npz + "
                             "signs.json, e.g. from `gesture-sim train --signs`; default: the "
                             "shipped one)")
    parser.add_argument("--transition", default="ramp", choices=TRANSITIONS,
                        help="how a segment switch is crossed: ramp (default: the switch ramp "
                             "in joint space) or gpdm (Chiu 2014's transitions on a GPDM of the "
                             "library's frames: fitted at start, ~3.5 s, then 0.05-0.2 s a "
                             "switch; methods with the timing layer)")
    parser.add_argument("--style", type=float, default=0.5,
                        help="style dial: 0 calm, 0.5 neutral (default), 1 energetic")
    parser.add_argument("--seed", type=int, default=0, help="seed (physics noise, baselines)")
    parser.add_argument("--workers", type=int, default=None,
                        help="parallel render processes (default: the number of CPUs)")
    parser.add_argument("--quality", default="standard", choices=("fast", "standard", "high"),
                        help="render quality preset (default standard)")
    parser.add_argument("--label", action="append", default=[], metavar="T:LABEL",
                        type=_label, help="request a semantic gesture at time T s, e.g. "
                        "2.5:wave (repeatable; labels: the library's tags, e.g. wave, bow, "
                        "bye, point, beckon)")
    parser.add_argument("--signals", type=Path, default=None, metavar="FILE",
                        help="face and head signal labels (RUTH markup: '1.2 nod', '2.0 brow', "
                             "'0.8-2.0 jog TL', '3.1 blink', '1.0 accent', 'auto off'; see "
                             "gesture_sim/signals/ruth.py) that drive or override the signals")
    parser.add_argument("--keywords", type=Path, default=None, metavar="FILE",
                        help="keyword table (JSON, or 'LABEL PHRASE [/threshold/]' lines) whose "
                             "spotted words request semantic gestures (default: the shipped "
                             "table; see `gesture-sim words --help`)")
    parser.add_argument("--no-keywords", action="store_true",
                        help="do not listen for keywords (gestures only from --label)")
    parser.add_argument("--transcript", type=Path, default=None, metavar="FILE",
                        help="aligned words (a TextGrid word tier or 'start end word' lines) "
                             "instead of the keyword spotter")
    parser.add_argument("--phones", default="auto", choices=("auto", "recognise", "off"),
                        help="where the lips' phones come from: auto (default) the "
                             "--transcript's (a TextGrid phone tier, or its words aligned to "
                             "the audio) or --text's, else phones recognised in the audio; "
                             "recognise: always those; off: none (the jaw opens with the "
                             "loudness)")
    parser.add_argument("--text", type=Path, default=None, metavar="FILE",
                        help="the transcript as plain text, force-aligned to the audio for the "
                             "lips (PocketSphinx and its CMU dictionary)")
    parser.add_argument("--no-face", action="store_true",
                        help="no face and head signals (nods, brows, blinks, jaw)")
    parser.add_argument("--look", default=DEFAULT_LOOK, choices=LOOKS,
                        help="the body drawn: human (default; a skinned MakeHuman body) or "
                             "mannequin (the capsules the physics collides with); the motion "
                             "is the same")
    parser.add_argument("--body", default="humanoid", metavar="BODY",
                        help="the body driven: humanoid (default), g1 (Unitree G1, 29 DoF), h1 "
                             "(Unitree H1) or a robot map file (.json, with its MJCF; see "
                             "docs/ROBOTS.md); a robot is drawn as its own model")
    parser.add_argument("--robot-export", type=Path, default=None, metavar="STEM.npz",
                        help="with a robot --body: its simulated joint trajectory at 50 Hz in "
                             "its motor order (STEM.npz, STEM.csv, STEM.pkl; docs/ROBOTS.md)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary")


def _label(text: str) -> tuple[float, str]:
    t, sep, label = text.partition(":")
    try:
        if not sep or not label:
            raise ValueError
        return float(t), label
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected T:LABEL such as 2.5:wave, got {text!r}") from None


def _interests(text: str) -> tuple[float, float]:
    """``X`` or ``X,Y`` (each 0..1) -> the two listeners' interests."""
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (1, 2) or not all(0.0 <= x <= 1.0 for x in values):
        raise argparse.ArgumentTypeError(
            f"expected X or X,Y with each in 0..1 (e.g. 0.2,0.9), got {text!r}")
    return (values[0], values[-1])


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "render", help="render a speech recording to an mp4 of the gesturing humanoid",
        description=(
            "Feed AUDIO through the causal pipeline (prosody -> CRF belief -> gesture controller "
            "-> PD-tracked MuJoCo humanoid) in simulated real time and render the simulated body "
            "headless (EGL) to an mp4 with the speech muxed in as AAC."),
    )
    parser.add_argument("audio", nargs="+", type=Path, metavar="AUDIO",
                        help="speech recording (WAV, or anything ffmpeg reads); several: a "
                             "batch (see 'many files')")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="output mp4; with several AUDIO files a folder that receives one "
                             "STEM.mp4 per input (A.wav -> OUT/A.mp4)")
    parser.add_argument("--timeline", type=Path, default=None,
                        help="also draw the timeline figure (PNG): prosody, belief, segments, "
                             "hand speed; with several AUDIO files a folder (STEM.png each)")
    parser.add_argument("--metrics", type=Path, default=None,
                        help="also write the plausibility metrics and the decision log (JSON); "
                             "with several AUDIO files a folder (STEM.json each)")
    parser.add_argument("--bvh", type=Path, default=None,
                        help="also write the simulated body's motion as BVH (30 fps, Y up, cm, "
                             "Mixamo-style joint names) for Blender or a game engine; with "
                             "several AUDIO files a folder (STEM.bvh each)")
    parser.add_argument("--npz", type=Path, default=None,
                        help="also write the simulation as numpy arrays: qpos, times, target "
                             "joints and the decision log; with several AUDIO files a folder "
                             "(STEM.npz each)")
    parser.add_argument("--smplx", type=Path, default=None, metavar="OUT.npz",
                        help="also write the motion as SMPL-X parameters in BEAT2's npz layout "
                             "(poses (T, 165) axis-angle, trans, betas, expressions, "
                             "mocap_frame_rate 30) for SMPL-X tools and BEAT2-trained systems; "
                             "with several AUDIO files a folder (STEM_smplx.npz each)")
    parser.add_argument("--mixamo", type=Path, default=None, metavar="OUT.bvh",
                        help="also write the motion as BVH on the Mixamo rig (mixamorig:* "
                             "joints with fingers, T-pose rest, 30 fps, Y up, cm) for BVH "
                             "tools (Blender, then a retarget step onto a Mixamo character; "
                             "Unity and Unreal import no BVH: use export --format fbx|glb); with "
                             "several AUDIO files a folder (STEM_mixamo.bvh each)")
    parser.add_argument("--to-skeleton", nargs=2, type=Path, default=None,
                        metavar=("SKELETON.bvh", "OUT.bvh"),
                        help="also write the motion as BVH on your own skeleton: OUT.bvh has "
                             "exactly the hierarchy, joint names, offsets and channels of "
                             "SKELETON.bvh (its motion is ignored; its joints found by the "
                             "importer's joint maps, its rest pose calibrated automatically); "
                             "with several AUDIO files OUT.bvh is a folder "
                             "(STEM_skeleton.bvh each)")
    many = parser.add_argument_group(
        "many files",
        "Several AUDIO files are rendered one after the other, or in parallel with --jobs or "
        "--dask; -o and the --timeline/--metrics/--bvh/--npz/--smplx/--mixamo/--to-skeleton "
        "folders may be "
        "the same folder. "
        "Every output path of every file is checked before any work starts (none may be an "
        "input or another output). A file that fails gives one error line naming it, the "
        "other files still finish, and the exit status is then 2. In a batch (and with "
        "--dask) --workers defaults to 1 (the files, not the frames, share the cores). For the "
        "same --seed and --workers the outputs are the same, byte for byte, with or without "
        "--jobs or --dask.")
    many.add_argument("--jobs", type=int, default=1, metavar="N",
                      help="render N files at a time, in N worker processes (one core each; "
                           "default 1)")
    many.add_argument("--dask", default=None, metavar="ADDRESS",
                      help="run the files as jobs on a Dask cluster: local (a local cluster of "
                           "one single-threaded worker process per CPU), local:N (N workers), "
                           "or a scheduler address such as tcp://host:8786 (paths are used as "
                           "given: every worker must see them). Needs gesture_sim[dask]")
    talk = parser.add_argument_group(
        "conversation (two people in one scene: each gestures in its own turns and listens, "
        "with nods and brow raises, in the other's)")
    talk.add_argument("--rttm", type=Path, default=None, metavar="FILE",
                      help="who speaks when in a mono AUDIO (a diarization in RTTM, as "
                           "pyannote and other diarizers write; the first two speakers)")
    talk.add_argument("--two", action="store_true",
                      help="AUDIO is stereo with one person per channel (left = person 0, "
                           "blue; right = person 1, red)")
    talk.add_argument("--listener", default="rule", choices=("rule", "okwechime"),
                      help="how a listener responds: rule (default; Ward & Tsukahara's pitch "
                           "rule at inviting pauses) or okwechime (Okwechime 2011's "
                           "audio-driven listener: MFCC classes of the partner's voice)")
    talk.add_argument("--listener-motion", default=None, choices=LISTENER_MOTIONS,
                      help="with --listener okwechime: what its states play: graph (default "
                           "when the library has them: real rests, nods and posture shifts "
                           "of the library's frames, Okwechime's motion graph) or envelope "
                           "(the rule's nod and lean curves)")
    talk.add_argument("--interest", type=_interests, default=(None, None), metavar="X[,Y]",
                      help="the listeners' interest, 0 (bored) .. 1 (interested), one value "
                           "for both or one per person (Okwechime 2011's interested vs "
                           "not-interested listener: more nods and silent 'mm' dips); "
                           "default: the rule's own rates")
    talk.add_argument("--interest-rules", type=Path, nargs=2, default=None,
                      metavar=("INTERESTED.json", "BORED.json"),
                      help="the listeners' tendencies from your own data: rules mined by "
                           "`gesture-sim listener mine` on interested and on not-interested "
                           "listeners (default: Okwechime 2011's Table 5.4 ratios)")
    add_render_options(parser)
    parser.set_defaults(func=run)


def check_render_options(args: argparse.Namespace) -> None:
    """Validate the options of :func:`add_render_options` (before any heavy import)."""
    from gesture_sim import validation as v

    v.frame_size(args.width, args.height)
    v.fps("--fps", args.fps)
    v.style("--style", args.style)
    v.seed("--seed", args.seed)
    v.workers("--workers", args.workers)
    v.labels("--label", args.label)
    if args.library is not None:
        v.input_folder("--library", args.library, "motion library folder")
    if args.model is not None:
        v.input_folder("--model", args.model, "model folder")
    if getattr(args, "keywords", None) is not None:
        v.input_file("--keywords", args.keywords, "keyword table")
    if getattr(args, "transcript", None) is not None:
        v.input_file("--transcript", args.transcript, "transcript")
    if getattr(args, "text", None) is not None:
        v.input_file("--text", args.text, "transcript text")
    check_method_options(args)
    if getattr(args, "signals", None) is not None:
        from gesture_sim.signals.ruth import load_markup

        load_markup(args.signals)   # a bad file: one line, before any work


def check_method_options(args: argparse.Namespace) -> None:
    """The options that only some methods read (from the method registry, :class:`~gesture_sim.
    methods.MethodSpec`): ``--sign-model`` (read here, so a damaged folder is one line before
    any work) only for a method with ``signs``, ``--transition gpdm`` only for one behind the
    timing layer (``timed``)."""
    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError
    from gesture_sim.methods import method_spec, methods_where

    spec = method_spec(args.method)
    if getattr(args, "sign_model", None) is not None:
        if not spec.signs:
            raise GestureSimError(
                f"--sign-model: read only by --method {', '.join(methods_where(signs=True))} "
                f"(not {args.method})")
        v.input_folder("--sign-model", args.sign_model, "sign model folder")
        from gesture_sim.inference.sign_model import SignModel

        try:
            SignModel.load(args.sign_model)
        except GestureSimError as exc:
            raise GestureSimError(f"--sign-model {exc}") from None
    if getattr(args, "transition", "ramp") != "ramp" and not spec.timed:
        raise GestureSimError(
            f"--transition {args.transition}: --method {args.method} has its own timing, "
            "which crosses its switches with the ramp; the transitions are for the methods "
            f"behind the timing layer ({', '.join(methods_where(timed=True))})")


def check_skeleton(path: Path, option: str = "--to-skeleton") -> None:
    """Read the skeleton of ``--to-skeleton SKELETON.bvh OUT.bvh`` before any work, so that one
    the exporter cannot take (duplicate joint names, non-finite offsets, no trunk or arms) is one
    line naming the option and the file, not a failure after the render."""
    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError
    from gesture_sim.export.skeleton import read_skeleton

    v.input_file(option, path, "BVH skeleton")
    try:
        read_skeleton(path)
    except GestureSimError as exc:
        text = str(exc)
        raise GestureSimError(f"{option}: {text}" if str(path) in text else
                              f"{option} {path}: {text}") from None


def _inputs(args: argparse.Namespace) -> list:
    """Every input path besides the audio, which no output may replace."""
    from gesture_sim import validation as v

    skeleton = getattr(args, "to_skeleton", None)
    return [*v.inputs_of(args, "keywords", "signals", "transcript", "text", "library", "model",
                         "rttm", "sign_model"), *(getattr(args, "interest_rules", None) or ()),
            *([skeleton[0]] if skeleton is not None else [])]


def _output_arg(args: argparse.Namespace, key: str) -> Path | None:
    """The path given for output ``key`` (for ``--to-skeleton``: its OUT.bvh)."""
    value = getattr(args, key, None)
    if key == "to_skeleton" and value is not None:
        return value[1]
    return value


def run(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v
    from gesture_sim.app.batch import check_dask, check_jobs
    from gesture_sim.errors import GestureSimError

    check_render_options(args)
    if args.two and args.rttm is not None:
        raise GestureSimError(
            "--two and --rttm: choose one: --two for a stereo AUDIO with one person per "
            "channel, --rttm FILE for who speaks when in a mono AUDIO")
    if args.rttm is None and not args.two and (args.listener != "rule"
                                               or args.interest != (None, None)
                                               or args.interest_rules is not None):
        raise GestureSimError("--listener / --interest / --interest-rules: a listener is one of "
                              "the two people of a conversation (--two or --rttm)")
    check_listener_motion(args.listener, args.listener_motion)
    check_jobs("--jobs", args.jobs)
    target = check_dask("--dask", args.dask) if args.dask is not None else None
    for audio in args.audio:
        v.input_file("AUDIO", audio, "audio file")
    if len(args.audio) > 1 or target is not None:
        return _run_batch(args, target)
    args.audio = args.audio[0]
    v.check_outputs([v.Output("-o/--output", args.output, v.VIDEO_EXTENSIONS),
                     v.Output("--timeline", args.timeline, v.PNG_EXTENSIONS)
                     if args.timeline is not None else None,
                     v.Output("--metrics", args.metrics, v.JSON_EXTENSIONS)
                     if args.metrics is not None else None,
                     *(v.Output(option, _output_arg(args, key), exts)
                       for option, key, exts, _ in _OUTPUTS[3:]
                       if _output_arg(args, key) is not None)],
                    inputs=[args.audio, *_inputs(args)])

    if args.rttm is not None or args.two:
        return _run_conversation(args)
    if args.to_skeleton is not None:
        check_skeleton(args.to_skeleton[0])
    summary = render_file(args.audio, args.output, show_progress=not args.json,
                          **_render_options(args))
    print_summary(summary, as_json=args.json)
    return 0


def _render_options(args: argparse.Namespace) -> dict:
    """The keyword arguments of :func:`~gesture_sim.app.render.render_speech` that every file
    of a run shares (all but the audio, the outputs and ``show_progress``)."""
    return dict(
        library=args.library, model=args.model, method=args.method, seed=args.seed,
        style=args.style, width=args.width, height=args.height, fps=args.fps,
        camera=args.camera, workers=args.workers, quality=args.quality,
        timeline=args.timeline, metrics=args.metrics, labels=tuple(args.label), bvh=args.bvh,
        npz=args.npz, smplx=args.smplx, mixamo=args.mixamo, signals_file=args.signals,
        face=not args.no_face, keywords=None if args.no_keywords else (args.keywords or "default"),
        transcript=args.transcript, look=args.look, phones=args.phones, text=args.text,
        sign_model=args.sign_model, transition=args.transition, body=args.body,
        robot_export=args.robot_export,
        to_skeleton=tuple(args.to_skeleton) if args.to_skeleton is not None else None,
    )


#: The outputs of one file: (option, render_speech keyword, extensions, suffix in a batch).
_OUTPUTS = (("-o/--output", "output", "VIDEO_EXTENSIONS", ".mp4"),
            ("--timeline", "timeline", "PNG_EXTENSIONS", ".png"),
            ("--metrics", "metrics", "JSON_EXTENSIONS", ".json"),
            ("--bvh", "bvh", (".bvh",), ".bvh"),
            ("--npz", "npz", (".npz",), ".npz"),
            ("--smplx", "smplx", (".npz",), "_smplx.npz"),
            ("--mixamo", "mixamo", (".bvh",), "_mixamo.bvh"),
            ("--to-skeleton", "to_skeleton", (".bvh",), "_skeleton.bvh"),
            ("--robot-export", "robot_export", (".npz",), "_robot.npz"))


def batch_outputs(args: argparse.Namespace) -> list[dict[str, Path | None]]:
    """The output paths of every file of ``render AUDIO... -o ...``, checked together before any
    work (:func:`gesture_sim.validation.check_outputs`): with one AUDIO the paths as given, with
    several each option names a folder and the files in it are named after the inputs
    (``A.wav`` -> ``OUT/A.mp4``, ``TIMELINE/A.png``, ...). Returns one
    ``{keyword: path or None}`` per AUDIO, in order."""
    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError

    several = len(args.audio) > 1
    folders = {}
    for option, key, _, suffix in _OUTPUTS:
        path = _output_arg(args, key)
        if path is None or not several:
            continue
        if path.is_dir():
            pass
        elif path.exists() or path.is_symlink():
            raise GestureSimError(f"{option} {path}: exists and is not a folder; with several "
                                  "AUDIO files it names a folder for one file per input")
        elif path.suffix.lower() == "." + suffix.rsplit(".", 1)[-1]:
            raise GestureSimError(
                f"{option} {path}: with several AUDIO files this is a folder (one {suffix} "
                f"per input, named after it); give a folder such as {path.with_suffix('')}")
        folders[key] = path
    per_file: list[dict[str, Path | None]] = []
    checks: list[v.Output | None] = []
    for audio in args.audio:
        paths: dict[str, Path | None] = {}
        for option, key, exts, suffix in _OUTPUTS:
            path = _output_arg(args, key)
            if path is not None and several:
                path = folders[key] / f"{audio.stem}{suffix}"
            paths[key] = path
            extensions = getattr(v, exts) if isinstance(exts, str) else exts
            name = f"{option} of {audio}" if several else option
            checks.append(v.Output(name, path, extensions) if path is not None else None)
        per_file.append(paths)
    v.check_outputs(checks, inputs=[*args.audio, *_inputs(args)])
    return per_file


def _run_batch(args: argparse.Namespace, target: DaskTarget | None) -> int:
    """``render A.wav B.wav ... -o DIR`` (or one file with ``--dask``): the files as jobs of
    :func:`gesture_sim.app.batch.run_jobs`, one progress bar, a line per file."""
    import sys
    import time

    from gesture_sim.app.batch import Job, run_jobs
    from gesture_sim.errors import GestureSimError

    several = len(args.audio) > 1
    if args.rttm is not None or args.two:
        raise GestureSimError("--rttm / --two: a conversation is rendered one AUDIO file at a "
                              "time" + (", not with --dask" if not several else ""))
    if args.transcript is not None and several:
        raise GestureSimError("--transcript: the aligned words of one recording; not with "
                              "several AUDIO files")
    if args.text is not None and several:
        raise GestureSimError("--text: the transcript of one recording; not with several "
                              "AUDIO files")
    outputs = batch_outputs(args)
    if args.to_skeleton is not None:   # render_speech takes (SKELETON.bvh, OUT.bvh)
        check_skeleton(args.to_skeleton[0])     # the shared skeleton once, before any render
        for paths in outputs:
            paths["to_skeleton"] = (args.to_skeleton[0], paths["to_skeleton"])
    options = _render_options(args)
    if options["workers"] is None:
        options["workers"] = 1   # one core per job: the files share the cores, not the frames
    jobs = [Job(str(audio), render_file, (audio,), {**options, **paths, "show_progress": False})
            for audio, paths in zip(args.audio, outputs, strict=True)]
    t0 = time.perf_counter()
    outcomes = run_jobs(jobs, n_jobs=args.jobs, dask=target, desc="render", unit="file",
                        show_progress=not args.json)
    wall = time.perf_counter() - t0
    failed = [o for o in outcomes if not o.ok]
    if args.json:
        print_json([o.value if o.ok else {"audio": o.label, "error": o.error}
                    for o in outcomes])
    elif not several and not failed:
        print_summary(outcomes[0].value, as_json=False)
    else:
        for o in outcomes:
            if o.ok:
                print(_batch_line(o.value, o.wall_s))
    for o in failed:
        print(f"gesture-sim: error: {o.line()}", file=sys.stderr)
    if not args.json and several:
        where = target.describe() if target is not None else (
            f"{min(args.jobs, len(jobs))} worker processes" if args.jobs > 1 else "serially")
        print(f"rendered {len(outcomes) - len(failed)} of {len(outcomes)} files in {wall:.1f} s "
              f"({where})" + (f"; failed: {', '.join(o.label for o in failed)}"
                              if failed else ""))
    return 2 if failed else 0


def render_file(audio: Path, output: Path, **options) -> dict:
    """One file of a batch (a job of :func:`gesture_sim.app.batch.run_jobs`, run in a worker):
    :func:`~gesture_sim.app.render.render_speech` with the heavy import done there."""
    from gesture_sim.app.render import render_speech

    return render_speech(audio, output, **options)


def _batch_line(summary: dict, wall_s: float) -> str:
    """One line per rendered file of a batch."""
    phys = summary.get("physics", {})
    return (f"wrote {summary['output']}: {summary['duration_s']:.1f} s, {summary['frames']} "
            f"frames, {summary['selection'].get('segments_played', 0)} segments; "
            f"fell={phys.get('fell')}, foot skating {_num(phys.get('foot_skate_mm_s'), 2)} mm/s; "
            f"{wall_s:.1f} s")


def _run_conversation(args: argparse.Namespace) -> int:
    """``render --rttm FILE`` / ``render --two``: the two-person scene."""
    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError

    unsupported = [name for name, given in (
        ("--label", args.label), ("--signals", args.signals), ("--keywords", args.keywords),
        ("--transcript", args.transcript), ("--bvh", args.bvh), ("--npz", args.npz),
        ("--smplx", args.smplx), ("--mixamo", args.mixamo),
        ("--to-skeleton", args.to_skeleton), ("--sign-model", args.sign_model),
        ("--transition gpdm", args.transition != "ramp"),
        ("--body", args.body != "humanoid"), ("--robot-export", args.robot_export))
        if given]
    if unsupported:
        raise GestureSimError(f"{', '.join(unsupported)}: not available for a conversation "
                              "(--rttm / --two) yet")
    if args.rttm is not None:
        v.input_file("--rttm", args.rttm, "RTTM file")
    tendencies = None
    if args.interest_rules is not None:
        from gesture_sim.signals.sdm import ListenerTendencies, load_rules

        for path in args.interest_rules:
            v.input_file("--interest-rules", path, "rules file")
        tendencies = ListenerTendencies.from_rules(*(load_rules(p) for p in args.interest_rules))
        if args.interest == (None, None):
            raise GestureSimError("--interest-rules: give the listeners' --interest too (0..1)")
    from gesture_sim.app.conversation import render_conversation

    summary = render_conversation(
        args.audio, args.output, rttm=args.rttm, library=args.library, model=args.model,
        method=args.method, seed=args.seed, style=args.style, width=args.width,
        height=args.height, fps=args.fps, camera="both" if args.camera == "front" else args.camera,
        workers=args.workers, quality=args.quality, timeline=args.timeline,
        metrics=args.metrics, show_progress=not args.json, face=not args.no_face,
        look=args.look, listener_model=args.listener, interests=args.interest,
        listener_tendencies=tendencies, listener_motion=args.listener_motion)
    if args.json:
        print_json(summary)
        return 0
    print(f"wrote {summary['output']}: {summary['duration_s']:.1f} s, {summary['frames']} "
          f"frames, two people, {len(summary['turns'])} turns")
    for p, person in enumerate(summary["people"]):
        phys = person.get("physics", {})
        rest = person.get("hands_in_partner_turns", {})
        print(f"  person {p}: speaks {person['speaking_s']:.1f} s, "
              f"{len(person['segments'])} segments, {len(person['backchannels'])} backchannels, "
              f"hands at rest {_num(100 * (rest.get('rest_share') or 0), 0)}% of the "
              f"partner's turns; fell={phys.get('fell')}, foot skating "
              f"{_num(phys.get('foot_skate_mm_s'), 2)} mm/s")
    print(f"  speed: pipeline {_num(summary.get('pipeline_realtime_factor'), 1)}x real time, "
          f"total {_num(summary.get('total_realtime_factor'), 2)}x")
    for key in ("timeline", "metrics"):
        if key in summary:
            print(f"  {key}: {summary[key]}")
    return 0


def print_summary(summary: dict, as_json: bool) -> None:
    """Print a render summary as JSON or as a few readable lines."""
    if as_json:
        print_json(summary)
        return
    sel = summary["selection"]
    phys = summary["physics"]
    print(f"wrote {summary['output']}: {summary['duration_s']:.1f} s, {summary['frames']} frames "
          f"at {summary['fps']:g} fps, {summary['size'][0]}x{summary['size'][1]}")
    print(f"  {summary['syllables']} syllables, {sel.get('segments_played', 0)} segments "
          f"({sel.get('distinct_segments', 0)} distinct, "
          f"{100 * sel.get('interrupted_share', 0):.0f}% interrupted)")
    print(f"  physics: fell={phys.get('fell')}, foot skating "
          f"{_num(phys.get('foot_skate_mm_s'), 2)} mm/s, hand error "
          f"{_num(phys.get('hand_error_settled_rms_mm'), 1)} mm RMS (settled)")
    print(f"  speed: pipeline {_num(summary.get('pipeline_realtime_factor'), 1)}x real time, "
          f"render {_num(summary.get('render_realtime_factor'), 2)}x, "
          f"total {_num(summary.get('total_realtime_factor'), 2)}x")
    for key in ("timeline", "metrics", "bvh", "npz", "smplx", "mixamo", "to_skeleton"):
        if key in summary:
            print(f"  {key}: {summary[key]}")


def _num(x: float | None, digits: int) -> str:
    """``x`` with ``digits`` decimals, or ``-`` when it is missing or not finite (a clip too
    short for a figure)."""
    import math

    if x is None or not isinstance(x, int | float) or not math.isfinite(x):
        return "-"
    return f"{x:.{digits}f}"
