"""``gesture-sim library build|info|preview``: make and inspect motion libraries."""

from __future__ import annotations

import argparse
import sys

from gesture_sim.commands import print_json


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "library", help="build, inspect and preview motion libraries",
        description="Motion libraries: mocap retargeted onto the humanoid and cut into gesture "
                    "segments.")
    lsub = parser.add_subparsers(dest="library_command", metavar="ACTION")

    b = lsub.add_parser("build", help="build a library from BVH / SMPL-X npz files",
                        description="Read, retarget, segment and parametrise motion files.")
    b.add_argument("inputs", nargs="+", metavar="INPUT", help=".bvh or SMPL-X .npz files")
    b.add_argument("-o", "--output", required=True, metavar="DIR", help="library folder to write")
    b.add_argument("--tags", metavar="FILE",
                   help='JSON {"<name pattern>": ["tag", ...]} (default: Bandai Namco gestures)')
    b.add_argument("--licence", help="licence of the inputs (default: guessed for known datasets)")
    b.add_argument("--fps", type=float, default=30.0, help="library frame rate (default 30)")
    b.add_argument("--threshold", type=float, default=None,
                   help="hand-speed threshold of the segmentation (m/s)")
    b.add_argument("--normalisation-from", metavar="FOLDER", dest="normalisation_from",
                   help="keep the kinematic-parameter normalisation (B_X / W_X) of this inference "
                   "model folder (or motion library folder) instead of fitting a new one, so that "
                   "model drives the new library without retraining, e.g. "
                   "motion_library/default/model for the shipped model; only the control layer "
                   "is then trained for the library (`gesture-sim library policy`, or on the "
                   "first render)")
    b.add_argument("--signs", metavar="FILE", action="append", default=None,
                   help="gestural-sign annotations (Chiu 2014's 14 signs, docs/SIGNS.md) for the "
                   "segments: a CSV with the header clip,start_s,end_s,sign or an ELAN "
                   "tab-delimited export (tier, begin, end, value; the tier or the file named as "
                   "the clip); a segment takes the sign covering at least half of it; may be "
                   "given more than once. Segments left unannotated are labelled by their form")
    b.add_argument("--json", action="store_true", help="print the summary as JSON")
    b.set_defaults(func=run_build)

    s = lsub.add_parser(
        "subset", help="a library of some clips of another library (same normalisation)",
        description="Copy the chosen clips of a library, with their segments, tags and "
                    "parameters, into a new library. The parameters keep the source's "
                    "normalisation, so every model that fits the source fits the subset; only "
                    "the control layer is trained for it (`gesture-sim library policy`).")
    s.add_argument("source", metavar="LIBRARY", help="library folder to take the clips from")
    s.add_argument("--clips", nargs="+", required=True, metavar="PATTERN",
                   help="clip names or fnmatch patterns (e.g. 2_scott_0_1_1 '*_bow_*')")
    s.add_argument("-o", "--output", required=True, metavar="DIR", help="library folder to write")
    s.add_argument("--json", action="store_true", help="print the summary as JSON")
    s.set_defaults(func=run_subset)

    q = lsub.add_parser(
        "policy", help="train the controller policy of a library for an inference model",
        description="Solve the controller MDP (the control layer) for a library and an existing "
                    "inference model, without touching the model: the policy is stored beside "
                    "the library (LIBRARY/policies/) unless the library is the model's own "
                    "(then MODEL/policy.npz). The model must fit the library (build it with "
                    "`library build --normalisation-from MODEL`).")
    q.add_argument("folder", metavar="LIBRARY", help="library folder")
    q.add_argument("--model", metavar="MODEL", default=None,
                   help="inference model folder (default: LIBRARY/model, else the shipped model "
                   "motion_library/default/model)")
    q.add_argument("--force", action="store_true", help="retrain even if a fitting policy exists")
    q.add_argument("--json", action="store_true", help="print the summary as JSON")
    q.set_defaults(func=run_policy)

    i = lsub.add_parser("info", help="summarise a library", description="Summarise a library.")
    i.add_argument("folder", metavar="DIR")
    i.add_argument("--json", action="store_true", help="print JSON")
    i.set_defaults(func=run_info)

    p = lsub.add_parser("preview", help="contact sheet of segment key poses",
                        description="Render the start pose of segments on the humanoid "
                                    "(headless, MUJOCO_GL=egl) into one PNG.")
    p.add_argument("folder", metavar="DIR")
    p.add_argument("-o", "--output", required=True, metavar="PNG")
    p.add_argument("--max", type=int, default=48, help="at most this many segments (default 48)")
    p.add_argument("--tag", help="only segments with this tag")
    p.add_argument("--columns", type=int, default=8)
    p.add_argument("--json", action="store_true", help="print what was rendered as JSON")
    p.set_defaults(func=run_preview)
    from gesture_sim.commands.mimic_graph import register_graph  # MIMiC (issue 18)

    register_graph(lsub)
    parser.set_defaults(func=lambda args: parser.print_help() or 1)


def _table(rows: list[list[str]], header: list[str]) -> str:
    widths = [max(len(str(r[k])) for r in [header, *rows]) for k in range(len(header))]
    fmt = lambda r: "  ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True))  # noqa: E731
    return "\n".join([fmt(header), fmt(["-" * w for w in widths]), *map(fmt, rows)])


def name_the_file(exc: Exception, path: str | None) -> Exception:
    """``exc`` with ``path:`` in front when its message does not name the file it is about
    (readers deep in the motion stage say "unknown skeleton" without knowing the file)."""
    from gesture_sim.errors import GestureSimError

    if path is None or str(path) in str(exc):
        return exc
    new = GestureSimError(f"{path}: {exc}")
    new.__cause__ = exc
    return new


def library_outputs(folder: str) -> list:
    """The outputs of a library folder ``-o DIR`` for
    :func:`gesture_sim.validation.check_outputs`: the folder and the two files written in it
    (a folder or an unreplaceable file there fails before the work)."""
    from pathlib import Path

    from gesture_sim import validation as v
    from gesture_sim.motion.finger_tracks import FINGER_TRACKS
    from gesture_sim.motion.library import ARRAYS, MANIFEST

    return [v.Output("-o/--output", folder, folder=True),
            *(v.Output("-o/--output", Path(folder) / name, within=folder)
              for name in (ARRAYS, MANIFEST, FINGER_TRACKS))]


def save_library(lib, folder: str) -> None:
    """``lib.save(folder)``; a failed save (a full disk, a signal) removes the folders it
    created (the files are written atomically by the library itself)."""
    from gesture_sim.fileio import new_folders_removed_on_error

    with new_folders_removed_on_error(folder):
        lib.save(folder)


def run_build(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v

    v.fps("--fps", args.fps)
    if args.threshold is not None:
        v.number("--threshold", args.threshold, 0.0, 10.0, lo_open=True, hint=" m/s")
    for f in args.inputs:
        v.motion_file("INPUT", f)
    if args.tags:
        v.input_file("--tags", args.tags, "JSON file")
    for f in args.signs or ():
        v.input_file("--signs", f, "sign annotation file (CSV or ELAN tab-delimited)")
    if args.normalisation_from is not None:
        v.input_folder("--normalisation-from", args.normalisation_from,
                       "model or library folder")
    v.check_outputs(library_outputs(args.output),
                    inputs=[*args.inputs, args.tags, args.normalisation_from,
                            *(args.signs or ())])

    from gesture_sim.loading import normalisation_from
    from gesture_sim.motion.build import build_library, load_tag_rules

    rules = load_tag_rules(args.tags)   # its own errors name the tags file, not a BVH
    from gesture_sim.motion import signs as sg

    annotations = [a for f in (args.signs or ()) for a in sg.read_sign_annotations(f)]
    if annotations:     # spans of another recording: one line before the build
        from pathlib import Path

        from gesture_sim.motion.build import motion_duration

        lengths = {Path(f).stem: motion_duration(f) for f in args.inputs}
        sg.check_annotation_times(annotations, {k: d for k, d in lengths.items()
                                                if d is not None})
    norm = (normalisation_from(args.normalisation_from)
            if args.normalisation_from is not None else None)
    from gesture_sim.motion.segmentation import SegmentationSettings
    from gesture_sim.progress import progress

    settings = SegmentationSettings() if args.threshold is None else SegmentationSettings(
        threshold=args.threshold)
    from gesture_sim.errors import GestureSimError

    bar = progress(total=len(args.inputs), desc="library", unit="file")
    done = [0]

    def on_clip(report) -> None:
        done[0] += 1
        bar.update(1)

    fingers: dict = {}
    try:
        lib, reports = build_library(
            args.inputs, rules, fps=args.fps, settings=settings,
            licence=args.licence, on_clip=on_clip, normalisation=norm, finger_tracks=fingers)
    except GestureSimError as exc:
        path = args.inputs[done[0]] if done[0] < len(args.inputs) else None
        raise name_the_file(exc, path) from None
    finally:
        bar.close()
    signs = None
    if args.signs:
        signs = sg.apply_sign_annotations(lib, annotations)
        lib.info = dict(lib.info, signs={"files": list(args.signs), "min_overlap": 0.5,
                                         "labelled": signs["labelled"],
                                         "unlabelled": signs["unlabelled"]})
    save_library(lib, args.output)
    if fingers:
        from gesture_sim.motion.finger_tracks import save_finger_tracks

        save_finger_tracks(args.output, lib, fingers)   # SMPL-X hand pose / BVH fingers
    summary = {
        "folder": args.output, "fingerprint": lib.fingerprint, "clips": len(lib.clips),
        "finger_tracks": sorted(fingers),
        "segments": len(lib.segments), "seconds": round(lib.duration, 2),
        "max_retarget_error": round(max(r.retarget_error for r in reports), 5),
        "normalisation_from": args.normalisation_from,
        "signs": signs,
        "files": [r.to_dict() for r in reports],
    }
    if args.json:
        print_json(summary)
        return 0
    rows = [[r.name, r.family, f"{r.seconds:.1f}", r.segments, f"{100 * r.retarget_error:.1f}%",
             f"{100 * r.retarget_error_p95:.1f}%"] for r in reports]
    print(_table(rows, ["clip", "skeleton", "seconds", "segments", "error", "error p95"]))
    print(f"\n{summary['clips']} clips, {summary['segments']} segments, {summary['seconds']} s "
          f"-> {args.output} (fingerprint {lib.fingerprint}); retarget error = hand/elbow "
          "position error as a fraction of arm length")
    if signs is not None:
        print(f"gestural signs: {signs['labelled']} of {len(lib.segments)} segments annotated "
              f"from {', '.join(args.signs)} ("
              + ", ".join(f"{k} {n}" for k, n in signs["counts"].items() if n)
              + f"); {signs['unlabelled']} unannotated (labelled by their form when asked)")
    if args.normalisation_from is not None:
        print(f"kinematic parameters normalised as {args.normalisation_from}: a model that fits "
              f"it drives this library; train only its control layer with `gesture-sim library "
              f"policy {args.output} --model MODEL` (or let the first render do it)")
    else:
        print("a new kinematic-parameter normalisation was fitted: train a model for it "
              f"(`gesture-sim train --library {args.output} ...`), or rebuild with "
              "--normalisation-from MODEL to keep an existing model (e.g. the shipped "
              "motion_library/default/model)")
    return 0


def run_subset(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v

    source = v.input_folder("LIBRARY", args.source, "motion library folder")
    v.check_outputs(library_outputs(args.output), inputs=[source])
    from gesture_sim.motion.finger_tracks import load_finger_tracks, save_finger_tracks
    from gesture_sim.motion.library import MotionLibrary

    src = MotionLibrary.load(source)
    lib = src.subset(args.clips)
    save_library(lib, args.output)
    src_names = [c.name for c in src.clips]
    tracks = {src_names[i]: t for i, t in load_finger_tracks(source, src).items()
              if src_names[i] in {c.name for c in lib.clips}}
    if tracks:
        save_finger_tracks(args.output, lib, tracks)      # the kept clips' finger motion
    summary = {"folder": args.output, "source": str(source), "fingerprint": lib.fingerprint,
               "clips": [c.name for c in lib.clips], "segments": len(lib.segments),
               "finger_tracks": sorted(tracks),
               "seconds": round(lib.duration, 2),
               "tags": sorted({t for seg in lib.segments for t in seg.tags})}
    if args.json:
        print_json(summary)
        return 0
    print(f"{len(lib.clips)} of {len(src.clips)} clips, {len(lib.segments)} segments, "
          f"{summary['seconds']} s -> {args.output} (fingerprint {lib.fingerprint}); "
          f"parameters normalised as {source}: train its control layer with "
          f"`gesture-sim library policy {args.output} --model MODEL`")
    return 0


def run_policy(args: argparse.Namespace) -> int:
    import time

    from gesture_sim import validation as v

    folder = v.input_folder("LIBRARY", args.folder, "motion library folder")
    model_dir = (v.input_folder("--model", args.model, "model folder") if args.model is not None
                 else None)
    from gesture_sim.control.policy import Policy
    from gesture_sim.errors import GestureSimError
    from gesture_sim.loading import (
        is_own_library,
        load_stack,
        policy_path,
        resolve_model_dir,
        save_policy,
        train_library_policy,
    )

    stack = load_stack(folder, resolve_model_dir(folder, model_dir), policy=False)  # fits?
    target = policy_path(stack.model_dir, stack.state_model, library_dir=folder,
                         own_library=is_own_library(stack.model, stack.library))
    policy, trained = None, False
    if not args.force and target.is_file():
        try:
            policy = Policy.load(target, stack.control_library.fingerprint,
                                 stack.state_model.fingerprint)
        except GestureSimError:
            policy = None
    t0 = time.perf_counter()
    if policy is None:
        policy = train_library_policy(stack.control_library, stack.state_model,
                                      show_progress=not args.json)
        trained = True
    train_s = time.perf_counter() - t0
    if trained:
        save_policy(policy, target)
    m = policy.meta
    summary = {"policy": str(target), "trained": trained,
               "train_s": round(train_s, 3) if trained else None,
               "solve_s": round(float(m.get("solve_seconds", 0.0)), 3),
               "table_s": round(float(m.get("table_seconds", 0.0)), 3),
               "library": str(folder), "library_fingerprint": policy.library_fingerprint,
               "model": str(stack.model_dir), "model_fingerprint": policy.model_fingerprint,
               "segments": policy.n_segments, "states": policy.n_states,
               "tones": list(policy.tones), "labels": [lab for lab in policy.labels if lab]}
    if args.json:
        print_json(summary)
        return 0
    what = (f"trained in {train_s:.2f} s" if trained
            else "already trained (use --force to retrain)")
    print(f"policy for library {folder} and model {stack.model_dir}: {what}; "
          f"{summary['segments']} segments, {summary['states']} states, labels "
          f"{', '.join(summary['labels']) or 'none'} -> {target}")
    return 0


def library_summary(lib) -> dict:
    """JSON-ready summary of a :class:`~gesture_sim.motion.library.MotionLibrary`."""
    import numpy as np

    lengths = np.array([s.length for s in lib.segments]) / lib.fps
    tags: dict[str, int] = {}
    for s in lib.segments:
        for t in s.tags:
            tags[t] = tags.get(t, 0) + 1
    # What the controller may choose without a label (co-speech: segments of untagged clips
    # that are no self-touch), what only a label brings (emblem strokes: tagged segments;
    # adaptors: self-touches, a hand at the head, face or neck) and the rest of the tagged
    # (acting) clips: their preparations and retractions.
    n = max(len(lib.segments), 1)
    kind, rule = segment_kinds(lib)
    total_s = max(float(lengths.sum()), 1e-9)
    kinds = {}
    for k in ("cospeech", "emblem", "adaptor", "acting"):
        mask = kind == k
        count, sec = int(mask.sum()), float(lengths[mask].sum()) if mask.any() else 0.0
        kinds[k] = {"segments": count, "share": round(count / n, 3),
                    "seconds": round(sec, 2), "seconds_share": round(sec / total_s, 3)}
    return {
        "segment_kinds": kinds,
        "fingerprint": lib.fingerprint, "fps": lib.fps, "joints": len(lib.joint_names),
        "clips": len(lib.clips), "segments": len(lib.segments),
        "seconds": round(lib.duration, 2),
        "segment_seconds": {"median": round(float(np.median(lengths)), 3),
                            "min": round(float(lengths.min()), 3),
                            "max": round(float(lengths.max()), 3)} if len(lengths) else {},
        "tags": tags,
        "signs": _sign_summary(lib, kind),
        "adaptor_rule": rule,
        "licences": sorted({c.licence for c in lib.clips}),
        "param_normalisation": lib.param_normalisation,
        "clip_list": [{"name": c.name, "seconds": round(c.n_frames / lib.fps, 2),
                       "segments": sum(1 for s in lib.segments if s.clip == k),
                       "tags": list(c.tags), "licence": c.licence, "source": c.source,
                       "retarget_error": c.retarget_error} for k, c in enumerate(lib.clips)],
    }


def _sign_summary(lib, kind) -> dict:
    """Per-sign segment counts (Chiu 2014, :mod:`gesture_sim.motion.signs`): stored annotations
    where the library has them, else the form labeller; ``realisable``: signs with at least one
    segment, ``realisable_cospeech``: with at least one co-speech segment."""
    from gesture_sim.errors import GestureSimError
    from gesture_sim.motion import signs as sg

    try:
        labels, source = sg.library_signs(lib)
    except GestureSimError as exc:      # not the humanoid's joints: nothing to pose
        return {"source": None, "why": str(exc)}
    co = [s for s, k in zip(labels, kind, strict=True) if k == "cospeech"]
    counts, co_counts = sg.sign_counts(labels), sg.sign_counts(co)
    return {"source": source, "counts": counts, "cospeech": co_counts,
            "realisable": [s for s, n in counts.items() if n],
            "realisable_cospeech": [s for s, n in co_counts.items() if n]}


def segment_kinds(lib) -> tuple:
    """((n_segments,) str array of "cospeech" / "emblem" / "adaptor" / "acting", the adaptor
    rule's figures or ``None``): co-speech = segments of untagged clips that are no self-touch,
    emblem = tagged segments, adaptor = self-touches, acting = the rest of the tagged clips."""
    import numpy as np

    untagged = np.array([not lib.clips[s.clip].tags for s in lib.segments], dtype=bool)
    adaptor, rule = _adaptors(lib, untagged)
    kind = np.array(["adaptor" if adaptor[i] else "cospeech" if untagged[i]
                     else "emblem" if s.tags else "acting" for i, s in enumerate(lib.segments)],
                    dtype=str)
    return kind, rule


def _adaptors(lib, candidates):
    """(n,) bool self-touch segments among ``candidates`` (a mask) and the rule's figures;
    none, and the rule ``None``, when the library's joints are not the humanoid's."""
    import numpy as np

    from gesture_sim.errors import GestureSimError
    from gesture_sim.motion import adaptors as ad

    try:
        found = ad.adaptor_segments(lib, np.nonzero(candidates)[0])
    except GestureSimError:
        return np.zeros(len(lib.segments), bool), None
    if found.any() and not (candidates & ~found).any():
        found[:] = False                # as the control layer: keep a co-speech segment
    return found, {"touch_gap_m": ad.TOUCH_GAP_M, "min_touch_share": ad.MIN_TOUCH_SHARE,
                   "min_hold_s": ad.MIN_HOLD_S, "label": ad.SELF_TOUCH_TAG}


def run_info(args: argparse.Namespace) -> int:
    from gesture_sim import validation as v

    v.input_folder("DIR", args.folder, "motion library folder")
    from gesture_sim.motion.library import MotionLibrary

    lib = MotionLibrary.load(args.folder)
    info = library_summary(lib)
    if args.json:
        print_json(info)
        return 0
    print(f"library {args.folder}: {info['clips']} clips, {info['segments']} segments, "
          f"{info['seconds']} s at {lib.fps:g} fps, fingerprint {info['fingerprint']}")
    if info["segment_seconds"]:
        s = info["segment_seconds"]
        print(f"segment length: median {s['median']} s (min {s['min']}, max {s['max']})")
    kinds = info["segment_kinds"]
    print("segments: " + ", ".join(
        f"{k} {v['segments']} ({100 * v['share']:.0f} %, {v['seconds']:g} s = "
        f"{100 * v['seconds_share']:.0f} %)" for k, v in kinds.items())
          + " — without a label the controller chooses among the co-speech ones")
    rule = info["adaptor_rule"]
    print("adaptors (self-touches, played only when asked for): " + (
        f"a hand within {100 * rule['touch_gap_m']:g} cm of the head, face or neck for at "
        f"least {100 * rule['min_touch_share']:g} % of a segment's frames or held there "
        f"for {rule['min_hold_s']:g} s"
        if rule else "not checked (the library's joints are not the humanoid's)"))
    print("tags: " + (", ".join(f"{k} ({v})" for k, v in sorted(info["tags"].items())) or "none"))
    signs = info["signs"]
    if signs.get("source"):
        print(f"gestural signs (Chiu 2014; {signs['source']}, see docs/SIGNS.md): co-speech "
              + (", ".join(f"{k} {n}" for k, n in signs["cospeech"].items() if n) or "none")
              + "; all segments " + ", ".join(f"{k} {n}" for k, n in signs["counts"].items() if n))
        missing = [s for s in signs["counts"] if s not in signs["realisable"]]
        print("signs the library can realise: " + ", ".join(signs["realisable"])
              + (f"; none for {', '.join(missing)}" if missing else ""))
    else:
        print(f"gestural signs: unlabelled ({signs.get('why', '')})")
    print("licences: " + "; ".join(info["licences"]))
    rows = [[c["name"], c["seconds"], c["segments"], ",".join(c["tags"]),
             "-" if c["retarget_error"] != c["retarget_error"]
             else f"{100 * c['retarget_error']:.1f}%"] for c in info["clip_list"]]
    print(_table(rows, ["clip", "seconds", "segments", "tags", "retarget error"]))
    return 0


def run_preview(args: argparse.Namespace) -> int:
    import numpy as np

    from gesture_sim import validation as v
    from gesture_sim.errors import GestureSimError
    from gesture_sim.fileio import atomic_path
    from gesture_sim.motion.library import MotionLibrary
    from gesture_sim.motion.preview import contact_sheet, render_poses

    v.input_folder("DIR", args.folder, "motion library folder")
    v.integer("--max", args.max, 1, 1000)
    v.integer("--columns", args.columns, 1, 64)
    (output,) = v.check_outputs([v.Output("-o/--output", args.output, v.PNG_EXTENSIONS)])
    lib = MotionLibrary.load(args.folder)
    chosen = [s.index for s in lib.segments if args.tag is None or args.tag in s.tags]
    if not chosen:
        raise GestureSimError(f"no segments{' with tag ' + args.tag if args.tag else ''} in "
                              f"{args.folder}")
    if len(chosen) > args.max:
        chosen = [chosen[int(k)] for k in np.linspace(0, len(chosen) - 1, args.max)]
    poses, labels = [], []
    for i in chosen:
        s = lib.segments[i]
        clip = lib.clips[s.clip]
        mid = s.start + s.interrupt_frames[1]  # the middle of the segment: its key pose
        poses.append((clip.qpos[mid], clip.root_pos[mid], clip.root_quat[mid]))
        labels.append(f"#{i} {clip.name[-24:]}\n{s.length / lib.fps:.2f}s {','.join(s.tags)}")
    images = render_poses(poses, lib.joint_names)
    sheet = contact_sheet(images, labels, columns=args.columns)
    import imageio.v3 as iio

    with atomic_path(output) as tmp:
        iio.imwrite(tmp, sheet, extension=".png")
    if args.json:
        print_json({"output": args.output, "segments": chosen, "size": list(sheet.shape[:2])})
    else:
        print(f"{len(chosen)} segment key poses -> {args.output}", file=sys.stdout)
    return 0
