"""``gesture-sim live``: the MuJoCo viewer driven by the microphone (or a file) in real time, or
the same loop without a window (``--headless``)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from gesture_sim.commands import print_json
from gesture_sim.commands.listener import LISTENER_MOTIONS, check_listener_motion
from gesture_sim.methods import METHODS
from gesture_sim.sim.looks import DEFAULT_LOOK, LOOKS

#: The hint given whenever there is no microphone to listen to.
NO_MIC_HINT = "use --audio FILE to play a recording through the live path"


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "live", help="open the viewer: the humanoid gestures to the microphone in real time",
        description=(
            "Open the interactive MuJoCo viewer and drive the simulated humanoid from the "
            "microphone (or, with --audio, from a recording played through the same live "
            "path and to the speakers). Keys in the window: +/- or Up/Down style dial, Space "
            "pause, R or Backspace reset, 1-9 semantic gestures. Close the window or press "
            "Ctrl-C to quit. With --headless the same loop runs without a window (for "
            "--stream to an engine or a robot on a machine without a display)."
        ),
    )
    parser.add_argument("--input-device", metavar="DEV",
                        help="input device: index or part of its name (default: the system "
                        "default input; see --list-devices)")
    parser.add_argument("--list-devices", action="store_true",
                        help="list the audio input devices and exit")
    parser.add_argument("--audio", metavar="FILE",
                        help="play this recording through the live path instead of the "
                        "microphone (for demos without a microphone)")
    parser.add_argument("--loop", action="store_true", help="with --audio: repeat the file")
    parser.add_argument("--mute", action="store_true",
                        help="with --audio: do not play the file to the speakers")
    parser.add_argument("--library", metavar="DIR", help="motion library (default: shipped)")
    parser.add_argument("--model", metavar="DIR", help="trained inference/control model "
                        "(default: shipped)")
    parser.add_argument("--method", default="controller", choices=METHODS,
                        help="selection method (default: controller; see render --help); "
                             "live there is no transcript: chiu14 hears the words as they are "
                             "said (see --no-words)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--style", type=float, default=0.5, metavar="X",
                        help="initial style dial, 0 = calm ... 1 = energetic (default 0.5)")
    parser.add_argument("--fps", type=float, default=60.0,
                        help="viewer sync rate in Hz (default 60)")
    parser.add_argument("--look", default=DEFAULT_LOOK, choices=LOOKS,
                        help="the body drawn: human (default) or mannequin (the colliders); "
                             "the motion is the same")
    parser.add_argument("--body", default="humanoid", metavar="BODY",
                        help="the body driven: humanoid (default), g1, h1 or a robot map .json "
                             "(docs/ROBOTS.md)")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="stop after S seconds (default: until the window is closed; "
                        "with --audio, until the file ends)")
    parser.add_argument("--screenshot", metavar="PNG",
                        help="save a picture of the viewer's camera when the loop ends")
    parser.add_argument("--stats", metavar="JSON",
                        help="write loop timing and memory figures to this JSON file")
    parser.add_argument("--keywords", metavar="FILE", default=None,
                        help="keyword table whose spotted words request semantic gestures "
                             "(default: the shipped table)")
    parser.add_argument("--no-keywords", action="store_true",
                        help="do not listen for keywords")
    parser.add_argument("--no-words", action="store_true",
                        help="with --method chiu14: do not recognise the words said (by default "
                             "PocketSphinx's continuous recogniser hears them in a worker "
                             "thread, each known about 0.3 s after it ends, and the sign filter "
                             "reads them; without it chiu14 runs on prosody alone); the --stats "
                             "JSON counts them under \"words\"")
    parser.add_argument("--listen", action="store_true",
                        help="the avatar listens instead of speaking: the microphone (or "
                             "--audio FILE) is the partner talking to it; it nods and raises "
                             "its brows at the pauses your speech invites, hands at rest")
    parser.add_argument("--phones", default="recognise", choices=("recognise", "off"),
                        help="the lips: recognise (default) phones in the audio as it comes "
                             "(PocketSphinx's phone loop; shown about 0.15 s late, its latency) "
                             "and form them; off: the jaw opens with the loudness")
    parser.add_argument("--listener", default="rule", choices=("rule", "okwechime"),
                        help="with --listen: how it responds (rule: Ward & Tsukahara's pitch "
                             "rule; okwechime: Okwechime 2011's audio-driven listener)")
    parser.add_argument("--listener-motion", default=None, choices=LISTENER_MOTIONS,
                        help="with --listen --listener okwechime: what its states play: graph "
                             "(default when the library has them: real rests, nods and posture "
                             "shifts of the library's frames) or envelope (the rule's curves)")
    parser.add_argument("--interest", type=float, default=None, metavar="X",
                        help="with --listen: its interest, 0 (bored) .. 1 (interested: more "
                             "nods and silent 'mm' dips); default: the rule's own rates "
                             "(= 0.5); in the viewer, ] and [ move it by 0.1")
    parser.add_argument("--headless", action="store_true",
                        help="run the live loop with no window (microphone or --audio): for "
                             "streaming the pose (--stream) to an engine or a robot on a "
                             "machine without a display; Ctrl-C stops it")
    parser.add_argument("--stream", metavar="ADDRESS",
                        help="also send the body's pose over UDP, at --stream-rate frames a "
                             "second on its own clock (whatever the viewer draws), each frame "
                             "stamped with its simulation time: HOST:PORT or "
                             "vmc://HOST:PORT in the VMC protocol (OSC) that VRM avatar "
                             "applications and their Unity/Unreal receivers read (their usual "
                             "port is 39539); json://HOST:PORT as one plain JSON datagram per "
                             "frame (root, joint angles, bone rotations; schema: "
                             "gesture_sim/export/json_stream.py) for any other program")
    parser.add_argument("--stream-rate", type=float, default=None, metavar="HZ",
                        help="with --stream: frames a second sent (default 60)")
    parser.add_argument("--json", action="store_true",
                        help="print the device list or the loop figures as JSON")
    parser.set_defaults(func=run)


def _print_devices(devices: list[dict[str, Any]], as_json: bool) -> None:
    if as_json:
        print_json({"input_devices": devices})
        return
    if not devices:
        print(f"no input device found; {NO_MIC_HINT}")
        return
    print(f"{'':2}{'index':>5}  {'name':<40} {'ch':>3} {'rate Hz':>8}  host API")
    for d in devices:
        mark = "*" if d.get("default") else " "
        print(f"{mark:2}{d['index']:>5}  {d['name'][:40]:<40} {d['channels']:>3} "
              f"{d['default_samplerate']:>8.0f}  {d['hostapi']}")
    print("(* = default input)")


def _summary(stats: dict[str, Any]) -> str:
    ft = stats["frame_time_ms"]
    mem = stats["memory"]
    return (f"live: {stats['wall_s']:.1f} s, {stats['frames']} frames ({stats['fps']:.1f} fps), "
            f"frame time {ft['mean']:.1f} ms (p95 {ft['p95']:.1f}, jitter {ft['jitter_std']:.1f}),"
            f" {stats['physics_steps_per_frame']['mean']:.1f} physics steps/frame, "
            f"{stats['percent_real_time']:.0f}% real time, "
            f"peak RSS {mem['maxrss_end_mb']:.0f} MiB; {stats['exit_reason']}"
            + (f"; heard {stats['words']['words']} words" if "words" in stats else "")
            + (f"; streamed {stats['stream']['frames_sent']} frames "
               f"({stats['stream'].get('protocol', 'vmc')}) to {stats['stream']['address']} "
               f"at {stats['stream'].get('sent_rate_hz', 0.0):.1f} Hz (largest gap "
               f"{stats['stream'].get('gap_max_ms', 0.0):.0f} ms, "
               f"{stats['stream']['frames_dropped']} dropped)"
               if "stream" in stats else ""))


def run(args: argparse.Namespace) -> int:
    from gesture_sim.audio import sources
    from gesture_sim.errors import GestureSimError
    from gesture_sim.methods import method_spec, methods_where

    if args.list_devices:
        try:
            devices = sources.list_input_devices()
        except GestureSimError:
            devices = []
        _print_devices(devices, args.json)
        return 0
    from gesture_sim import validation as v
    from gesture_sim.app.pose_clock import DEFAULT_RATE_HZ, MAX_RATE_HZ

    v.style("--style", args.style)
    v.seed("--seed", args.seed)
    v.fps("--fps", args.fps)
    if args.stream_rate is not None:
        if args.stream is None:
            raise GestureSimError("--stream-rate needs --stream ADDRESS")
        v.number("--stream-rate", args.stream_rate, 0.0, MAX_RATE_HZ, lo_open=True,
                 hint=" frames a second")
    if args.duration is not None:
        v.number("--duration", args.duration, 0.0, 7 * 86400.0, lo_open=True, hint=" seconds")
    if args.audio:
        v.input_file("--audio", args.audio, "audio file")
    elif args.loop or args.mute:
        raise GestureSimError("--loop and --mute need --audio FILE")
    if args.keywords is not None:
        v.input_file("--keywords", args.keywords, "keyword table")
    if args.no_words and not method_spec(args.method).signs:
        raise GestureSimError(
            f"--no-words: only --method {', '.join(methods_where(signs=True))} recognises the "
            f"words said (its sign filter reads them); --method {args.method} hears none")
    if args.interest is not None:
        v.number("--interest", args.interest, 0.0, 1.0)
    if not args.listen and (args.interest is not None or args.listener != "rule"):
        raise GestureSimError("--listener / --interest: for an avatar that listens (--listen)")
    check_listener_motion(args.listener, args.listener_motion)
    from gesture_sim.sim.bodies import resolve_body

    resolve_body(args.body)                  # an unknown body fails before any device opens
    for name in ("library", "model"):
        if getattr(args, name):
            v.input_folder(f"--{name}", getattr(args, name))
    v.check_outputs([v.Output("--screenshot", args.screenshot, v.PNG_EXTENSIONS)
                     if args.screenshot else None,
                     v.Output("--stats", args.stats, v.JSON_EXTENSIONS) if args.stats else None],
                    inputs=[args.audio, *v.inputs_of(args, "keywords", "library", "model")])

    from gesture_sim.app import live, viewer
    from gesture_sim.audio import feeds

    stream = None
    if args.stream is not None:  # a bad (or empty) address: one line, before anything loads
        from gesture_sim.export.streams import open_stream

        stream = open_stream(args.stream)

    # 1. the audio source (a missing microphone is the commonest problem: say so first)
    if args.audio:
        feed: Any = feeds.FileFeed(args.audio, loop=args.loop, speakers=not args.mute)
    else:
        try:
            mic = sources.MicrophoneSource(device=args.input_device)
        except GestureSimError as exc:
            msg = str(exc)
            if "no audio input device" in msg or "PortAudio" in msg:
                raise GestureSimError(f"no input device found; {NO_MIC_HINT}") from exc
            raise
        feed = feeds.MicrophoneFeed(mic)
    # 2. a window to draw in (none with --headless)
    if not args.headless:
        viewer.check_display()
    # 3. the pipeline (the heavy part)
    from gesture_sim.pipeline import GesturePipeline

    # record=False: no trace, a bounded log — memory stays flat over a long run
    pipeline: Any = GesturePipeline.create(
        library=args.library, model=args.model, method=args.method, seed=args.seed,
        style=args.style, record=False,
        listener=args.listen, look=args.look, listener_model=args.listener,
        interest=args.interest, listener_motion=args.listener_motion,
        phones="recognise" if args.phones == "recognise" and not args.listen else None,
        body=args.body)
    if args.listen:
        from gesture_sim.app.listening import ListeningPipeline

        pipeline = ListeningPipeline(pipeline)
    options = live.LiveOptions(
        duration=args.duration, fps=args.fps, style=args.style,
        final_screenshot=args.screenshot, stats_path=args.stats,
        print_keys=not args.json, out=sys.stderr if args.json else sys.stdout, stream=stream,
        stream_rate=args.stream_rate if args.stream_rate is not None else DEFAULT_RATE_HZ,
        headless=args.headless,
    )
    spotter = words = None
    try:
        if not args.no_keywords and not args.listen:   # a listener's words are not its own
            from gesture_sim.audio.keywords import (
                KeywordSpotter,
                KeywordTable,
                check_keyword_labels,
            )

            table = KeywordTable.load(args.keywords)
            from gesture_sim.methods import no_labels_note

            check_keyword_labels(table, pipeline.labels, explicit=args.keywords is not None,
                                 none=no_labels_note(args.method, pipeline.library))
            spotter = KeywordSpotter(table, labels=pipeline.labels)
            if not spotter.active:
                spotter.close()
                spotter = None
        if method_spec(args.method).signs and not args.no_words and not args.listen:
            from gesture_sim.audio.live_words import LiveWords

            words = LiveWords()
        # run_live closes the spotter and the recogniser, however the loop ends
        stats = live.run_live(pipeline, feed, options, spotter=spotter, words=words).to_dict()
    finally:
        for worker in (spotter, words):    # failed before the loop: no orphan worker thread
            if worker is not None:
                worker.close()
        if stream is not None:
            stream.close()
    if args.json:
        print_json(stats)
    else:
        print(_summary(stats))
    sent = stats.get("stream", {})
    if sent and sent.get("frames_sent", 0) == 0 and sent.get("frames_dropped", 0) > 0:
        raise GestureSimError(f"--stream {args.stream}: no frame went out ("
                              f"{sent['frames_dropped']} refused: "
                              f"{sent.get('last_error') or 'unknown error'})")
    return 0
