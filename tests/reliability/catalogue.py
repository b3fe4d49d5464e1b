"""The reliability catalogue: hostile and odd command lines, one row each.

A row is ``(id, command line, expected exit status, expected substring, files that must stay
unchanged)``. The command line is a string split with :func:`shlex.split` after
``{name}`` placeholders are filled: ``{audio.good}`` and the other generated files of
:mod:`tests.reliability.badfiles`, ``{new}`` a fresh empty folder per row (for outputs that must
not appear). The substring is looked for in stderr for a failing row (``gesture-sim: error:``
is always required there) and in stdout for a row that succeeds. Every file named on the
command line must be unchanged afterwards unless the row lists it as written (``writes``).
"""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Row:
    """One catalogue case (see the module docstring)."""

    id: str
    cmd: str
    rc: int
    expect: str
    unchanged: tuple[str, ...] = ()
    writes: tuple[str, ...] = field(default=())


ROWS: list[Row] = []


def row(id: str, cmd: str, rc: int, expect: str, unchanged: tuple[str, ...] = (),
        writes: tuple[str, ...] = ()) -> None:
    ROWS.append(Row(id, cmd, rc, expect, unchanged, writes))


A = "{audio.good}"
NEW_MP4 = "{new}/out.mp4"

# ------------------------------------------------------------------ render: numbers
for v, msg in [("nan", "--fps must be a number from 1 to 240"), ("inf", "--fps must be"),
               ("-inf", "--fps must be"), ("0", "--fps must be"), ("-1", "--fps must be"),
               ("1e9", "--fps must be"), ("0.5", "--fps must be"), ("241", "--fps must be"),
               ("1e400", "--fps must be")]:
    row(f"render-fps-{v}", f"render {A} -o {NEW_MP4} --fps={v}", 2, msg)
for opt, v in [("--width", "0"), ("--width", "-2"), ("--width", "14"), ("--width", "17"),
               ("--width", "99999"), ("--width", "1281"), ("--height", "0"),
               ("--height", "9999"), ("--height", "721"), ("--height", "-720")]:
    row(f"render{opt}-{v}", f"render {A} -o {NEW_MP4} {opt} {v}", 2, f"{opt} must be")
for v in ["5", "-0.1", "1.01", "nan", "inf", "-inf", "9"]:
    row(f"render-style-{v}", f"render {A} -o {NEW_MP4} --style={v}", 2,
        "--style must be a number from 0 to 1")
for v in ["-1", "4294967296", "1099511627776"]:
    row(f"render-seed-{v}", f"render {A} -o {NEW_MP4} --seed {v}", 2,
        "--seed must be an integer from 0 to 4294967295")
for v in ["0", "-1", "1000"]:
    row(f"render-workers-{v}", f"render {A} -o {NEW_MP4} --workers {v}", 2,
        "--workers must be an integer from 1 to 64")
for v, msg in [("-1:wave", "--label time of 'wave' must be"), ("nan:wave", "--label time"),
               ("inf:wave", "--label time"), ("999:wave", "seconds within the 4.00 s audio"),
               ("1e308:wave", "--label time"), ("4.5:wave", "seconds within the 4.00 s audio"),
               ("x:wave", "expected T:LABEL"), ("2.0:", "expected T:LABEL"),
               ("wave", "expected T:LABEL"), ("1.0:nosuchlabel", "unknown semantic label")]:
    row(f"render-label-{v}", f"render {A} -o {NEW_MP4} --label={v}", 2, msg)
row("render-camera-top", f"render {A} -o {NEW_MP4} --camera top", 2, "--camera must be one of")
row("render-camera-empty", f"render {A} -o {NEW_MP4} --camera ''", 2, "--camera must be one of")
row("render-quality", f"render {A} -o {NEW_MP4} --quality ultra", 2, "invalid choice")
row("render-method", f"render {A} -o {NEW_MP4} --method foo", 2, "invalid choice")
row("render-no-output", f"render {A}", 2, "required")
row("render-fps-text", f"render {A} -o {NEW_MP4} --fps fast", 2, "invalid float value")

# ------------------------------------------------------------------ render: outputs
G, OLD, OLDJ = "{audio.good}", "{out.old_mp4}", "{out.old_json}"
for id_, cmd, msg, keep in [
    ("o-is-input", f"render {G} -o {G}", "is the input file", (G,)),
    ("metrics-is-input", f"render {G} -o {NEW_MP4} --metrics {G}", "is the input file", (G,)),
    ("timeline-is-input", f"render {G} -o {NEW_MP4} --timeline {G}", "is the input file", (G,)),
    ("metrics-is-output", f"render {G} -o {OLD} --metrics {OLD}", "is also the path of", (OLD,)),
    ("timeline-is-output", f"render {G} -o {OLD} --timeline {OLD}", "is also the path of",
     (OLD,)),
    ("metrics-links-to-output", f"render {G} -o {OLD} --metrics {{out.link_to_old_mp4}}",
     "is also the path of", (OLD,)),
    ("o-existing-folder", f"render {G} -o {{out.dir_mp4}}", "is an existing folder", ()),
    ("metrics-existing-folder", f"render {G} -o {OLD} --metrics {{out.dir_json}}",
     "is an existing folder", (OLD,)),
    ("timeline-existing-folder", f"render {G} -o {OLD} --timeline {{out.dir_png}}",
     "is an existing folder", (OLD,)),
    ("o-fifo", f"render {G} -o {{out.fifo_mp4}}", "is a FIFO", ()),
    ("o-dev-null", f"render {G} -o /dev/null", "is a device", ()),
    ("o-symlink-to-input", f"render {G} -o {{out.link_to_input}}", "is the input file", (G,)),
    ("o-gif", f"render {G} -o {{new}}/x.gif", "unsupported file type '.gif'", ()),
    ("o-txt", f"render {G} -o {{new}}/x.txt", "unsupported file type '.txt'", ()),
    ("o-wav", f"render {G} -o {{new}}/x.wav", "unsupported file type '.wav'", ()),
    ("o-no-extension", f"render {G} -o {{new}}/video", "unsupported file type", ()),
    ("timeline-svg", f"render {G} -o {NEW_MP4} --timeline {{new}}/t.svg",
     "unsupported file type '.svg'", ()),
    ("metrics-txt", f"render {G} -o {NEW_MP4} --metrics {{new}}/m.txt",
     "unsupported file type '.txt'", ()),
    ("o-under-a-file", f"render {G} -o {{out.file_as_folder}}/x.mp4", "is a file",
     ("{out.file_as_folder}",)),
    ("o-empty", f"render {G} -o ''", "is not a file name", ()),
    ("o-dot", f"render {G} -o .", "is not a file name", ()),
    ("o-hardlink-to-input", f"render {G} -o {{audio.hardlink}}", "is the input file", (G,)),
]:
    row(f"render-{id_}", cmd, 2, msg, keep)

# ------------------------------------------------------------------ render: inputs
for name, msg in [
    ("empty", "empty file (0 bytes)"), ("header_only", "contains no samples"),
    ("truncated_header", "not a readable WAV file"), ("nan", "every sample is NaN or infinite"),
    ("inf", "every sample is NaN or infinite"), ("huge_float", "far outside [-1, 1]"),
    ("rate_1hz", "too low for speech"), ("rate_7hz", "too low for speech"),
    ("rate_zero", "invalid sample rate"), ("channels_zero", "not a readable WAV file"),
    ("riff_not_wave", "not WAVE audio"), ("wrong_magic", "not a readable WAV file"),
    ("random_bytes", "not an audio file"), ("text", "not an audio file"),
    ("mp3_named_text", "not an audio file"), ("png_as_wav", "not an audio file"),
    ("folder", "is a folder"), ("missing", "no such file"), ("fifo", "is a FIFO"),
    ("dev_zero", "is a device"), ("dev_null", "is a device"), ("silent", "silent"),
]:
    row(f"render-audio-{name}", f"render {{audio.{name}}} -o {NEW_MP4}", 2, msg)
row("render-audio-missing-dir", f"render /no/such/dir/a.wav -o {NEW_MP4}", 2, "no such file")

# ------------------------------------------------------------------ render: libraries, models
# (each of these loads a library or a model: a representative few here; ``library info`` below
# has every damaged library, the in-process tests every damaged policy)
for name, msg in [
    ("npz_truncated", "damaged motion library arrays (truncated"),
    ("npz_garbage", "not a NumPy .npz archive"), ("manifest_list", "not a JSON object"),
    ("manifest_no_joints", "missing entry 'joint_names'"), ("no_npz", "library.npz is missing"),
]:
    row(f"render-library-{name}", f"render {A} -o {NEW_MP4} --library {{lib.{name}}}", 2, msg)
for name, msg in [
    ("npz_truncated", "damaged inference model (truncated"),
    ("npz_pickle", "not a NumPy .npz archive"), ("npz_keys", "missing entry"),
    ("json_truncated", "invalid JSON"), ("json_list", "not a JSON object"),
    ("json_no_settings", "missing entry 'settings'"), ("no_json", "is not an inference model"),
]:
    row(f"render-model-{name}", f"render {A} -o {NEW_MP4} --model {{model.{name}}}", 2, msg)
row("render-library-is-file", f"render {A} -o {NEW_MP4} --library {A}", 2, "is a file")
row("render-library-missing", f"render {A} -o {NEW_MP4} --library /no/such/lib", 2,
    "no such folder")
row("render-model-missing", f"render {A} -o {NEW_MP4} --model /no/such/model", 2,
    "no such folder")

# ------------------------------------------------------------------ demo
for id_, args, msg in [
    ("fps-nan", "--fps nan", "--fps must be"), ("fps-inf", "--fps inf", "--fps must be"),
    ("seed-neg", "--seed -1", "--seed must be"), ("style-5", "--style 5", "--style must be"),
    ("width-huge", "--width 99999", "--width must be"), ("label-past-end", "--label 999:wave",
                                                        "seconds within the"),
    ("o-dot", "-o .", "is not a file name"), ("o-gif", "-o {new}/demo.gif",
                                               "unsupported file type '.gif'"),
    ("o-existing-folder", "-o {out.dir_mp4}", "is an existing folder"),
    ("timeline-is-folder", "-o {out.demo_dir}/demo.mp4", "is an existing folder"),
    ("workers-0", "--workers 0", "--workers must be"),
]:
    row(f"demo-{id_}", f"demo {args}", 2, msg)

# ------------------------------------------------------------------ prosody
for name, msg in [
    ("empty", "empty file"), ("header_only", "contains no samples"), ("nan", "NaN or infinite"),
    ("inf", "NaN or infinite"), ("rate_1hz", "too low for speech"),
    ("truncated_header", "not a readable WAV"), ("random_bytes", "not an audio file"),
    ("folder", "is a folder"), ("missing", "no such file"), ("fifo", "is a FIFO"),
    ("dev_zero", "is a device"), ("channels_zero", "not a readable WAV"),
    ("huge_float", "far outside"), ("riff_not_wave", "not WAVE audio"),
]:
    row(f"prosody-bad-{name}", f"prosody {{audio.{name}}}", 2, msg)
for name in ["good", "truncated_mid", "short_0_2s", "some_nan", "float64", "rate_8k",
             "rate_384k", "width8", "width24", "width32", "stereo", "six_channels", "unicode",
             "bits_13"]:
    row(f"prosody-ok-{name}", f"prosody {{audio.{name}}}", 0, "syllables")
for name in ["silent", "short_10ms", "one_sample", "truncated_tiny"]:
    row(f"prosody-nospeech-{name}", f"prosody {{audio.{name}}}", 0, "no speech found")
row("prosody-json-short", "prosody {audio.short_0_2s} --json", 0, '"speech_found"')
for v in ["0", "-1", "99999"]:
    row(f"prosody-block-{v}", f"prosody {A} --block-size {v}", 2, "--block-size must be")
row("prosody-plot-folder", f"prosody {A} --plot {{out.dir_png}}", 2, "is an existing folder")
row("prosody-plot-input", f"prosody {A} --plot {A}", 2, "is the input file", (A,))
row("prosody-plot-txt", f"prosody {A} --plot {{new}}/p.txt", 2, "unsupported file type")

# ------------------------------------------------------------------ library info / preview
for name, msg in [
    ("npz_truncated", "truncated"), ("npz_empty", "damaged motion library"),
    ("npz_garbage", "not a NumPy .npz archive"), ("npz_pickle", "not a NumPy .npz archive"),
    ("npz_text", "not a NumPy .npz archive"), ("npz_keys", "missing entry"),
    ("manifest_list", "not a JSON object"), ("manifest_no_joints", "'joint_names'"),
    ("manifest_no_clips", "'clips'"), ("manifest_wrong_version", "format version 999"),
    ("manifest_wrong_format", "not a motion library manifest"),
    ("manifest_bad_fingerprint", "fingerprint"), ("manifest_clips_string", "damaged"),
    ("manifest_fps_string", "damaged"), ("manifest_truncated", "invalid JSON"),
    ("manifest_empty", "invalid JSON"), ("manifest_binary", "invalid JSON"),
    ("no_manifest", "no manifest.json"), ("no_npz", "library.npz is missing"),
]:
    row(f"library-info-{name}", f"library info {{lib.{name}}}", 2, msg)
row("library-info-file", f"library info {A}", 2, "is a file")
row("library-info-missing", "library info /no/such/library", 2, "no such folder")
for id_, args, msg in [
    ("max-0", "--max 0", "--max must be"), ("columns-0", "--columns 0", "--columns must be"),
    ("o-folder", "-o {out.dir_png}", "is an existing folder"),
    ("o-txt", "-o {new}/sheet.txt", "unsupported file type"),
]:
    out = "" if "-o" in args else " -o {new}/sheet.png"
    row(f"library-preview-{id_}", f"library preview {{lib.npz_keys}} {args}{out}", 2, msg)
row("library-preview-damaged", "library preview {lib.npz_truncated} -o {new}/s.png", 2,
    "damaged motion library")

# ------------------------------------------------------------------ library build
B = "{motion.good_bvh}"
for id_, args, msg in [
    ("fps-0", "--fps 0", "--fps must be"), ("fps-nan", "--fps nan", "--fps must be"),
    ("fps-inf", "--fps inf", "--fps must be"), ("fps-neg", "--fps -30", "--fps must be"),
    ("threshold-0", "--threshold 0", "--threshold must be"),
    ("threshold-nan", "--threshold nan", "--threshold must be"),
    ("threshold-neg", "--threshold -1", "--threshold must be"),
    ("tags-missing", "--tags /no/tags.json", "no such file"),
    ("tags-bad-json", "--tags {motion.tags_bad_json}", "cannot read tags file"),
    ("tags-list", "--tags {motion.tags_list}", "must map name patterns"),
]:
    row(f"library-build-{id_}", f"library build {B} -o {{new}}/lib {args}", 2, msg, (B,))
for name, msg in [("bvh_empty", "no HIERARCHY section"), ("bvh_header_only", "no MOTION"),
                  ("bvh_no_frames", "Frames: must be a positive integer"),
                  ("bvh_truncated", "truncated motion"), ("bvh_text", "no HIERARCHY"),
                  ("bvh_frame_time_zero", "is not a number"),
                  ("bvh_nan", "NaN or infinite values"),
                  ("npz_garbage", "not a NumPy .npz archive"),
                  ("npz_empty_archive", "has no 'poses' array"),
                  ("txt_motion", "unsupported motion file type"),
                  ("bvh_unknown_skeleton", "unknown_skeleton.bvh: unknown skeleton")]:
    row(f"library-build-bad-{name}", f"library build {{motion.{name}}} -o {{new}}/lib", 2,
        msg, (f"{{motion.{name}}}",))
row("train-pair-garbage-npz", "train --pair {motion.npz_garbage} {audio.good} -o {new}/m", 2,
    "not a NumPy .npz archive")
row("library-build-missing", "library build /no/such.bvh -o {new}/lib", 2, "no such file")
row("library-build-folder-input", "library build {out.dir_mp4} -o {new}/lib", 2, "is a folder")
row("library-build-o-file", f"library build {B} -o {{out.file_report}}", 2,
    "exists and is not a folder", ("{out.file_report}",))
row("library-build-o-is-input", f"library build {B} -o {B}", 2, "exists and is not a folder",
    (B,))

# ------------------------------------------------------------------ train
P = "--pair {motion.good_bvh} {audio.good}"
for id_, args, msg in [
    ("rate-inf", "--rate inf", "--rate must be"), ("rate-nan", "--rate nan", "--rate must be"),
    ("rate-0", "--rate 0", "--rate must be"), ("rate-neg", "--rate -30", "--rate must be"),
    ("rate-huge", "--rate 1e9", "--rate must be"), ("states-1", "--states 1", "--states must be"),
    ("states-65", "--states 65", "--states must be"),
    ("clusters-0", "--clusters 0", "--clusters must be"),
    ("window-0", "--window 0", "--window must be"), ("seed-neg", "--seed -1", "--seed must be"),
    ("library-missing", "--library /no/lib", "no such folder"),
]:
    row(f"train-{id_}", f"train {P} -o {{new}}/model {args}", 2, msg)
row("train-pair-missing-motion", "train --pair /no/m.bvh {audio.good} -o {new}/m", 2,
    "no such file")
row("train-pair-missing-audio", "train --pair {motion.good_bvh} /no/a.wav -o {new}/m", 2,
    "no such file")
row("train-pair-dev-zero", "train --pair {motion.good_bvh} /dev/zero -o {new}/m", 2,
    "is a device")
row("train-o-file", f"train {P} -o {{out.file_report}}", 2, "exists and is not a folder",
    ("{out.file_report}",))
row("train-o-is-input", f"train {P} -o {{audio.good}}", 2, "exists and is not a folder",
    ("{audio.good}",))
row("train-no-pair", "train -o {new}/m", 2, "required")
row("train-pair-mismatch", "train --pair {motion.good_bvh} {audio.long} -o {new}/m", 2,
    "a pair must be the motion and speech of the same take")
# train --corpus (issue 35 item 1): bad corpora fail before anything is written
row("train-corpus-missing", "train --corpus /no/such/dir -o {new}/m", 2, "no such folder")
row("train-corpus-is-a-file", "train --corpus {audio.good} -o {new}/m", 2,
    "is a file, not a corpus folder")
row("train-corpus-empty", "train --corpus {new} -o {new}/m", 2, "no motion/speech pair found")
row("train-corpus-and-pair", f"train --corpus {{new}} {P} -o {{new}}/m", 2,
    "not allowed with argument")
row("train-corpus-no-output", "train --corpus {new}", 2, "-o/--output is required")
row("train-corpus-jobs-0", "train --corpus {new} -o {new}/m --jobs 0", 2, "--jobs must be")
row("train-corpus-on-error", "train --corpus {new} -o {new}/m --on-error maybe", 2,
    "invalid choice")
row("train-corpus-dask-empty", "train --corpus {new} -o {new}/m --dask ''", 2,
    "--dask must be local, local:N")
row("train-corpus-library", "train --corpus {new} -o {new}/m --library {new}", 2,
    "--library cannot be used with --corpus")
row("train-speaker-without-corpus", f"train {P} -o {{new}}/m --speaker scott", 2,
    "--speaker needs --corpus")

# ------------------------------------------------------------------ eval
for id_, args, msg in [
    ("seeds-0", f"motion {A} --seeds 0", "--seeds must be"),
    ("seeds-101", f"motion {A} --seeds 101", "--seeds must be"),
    ("audio-missing", "motion /no/such.wav", "no such file"),
    ("audio-dev-zero", "motion /dev/zero", "is a device"),
    ("audio-folder", "motion {out.dir_mp4}", "is a folder"),
    ("report-file", f"motion {A} --report {{out.file_report}}", "exists and is not a folder"),
    ("report-is-input", f"motion {A} --report {A}", "exists and is not a folder"),
    ("reference-missing", f"motion {A} --reference /no/ref.bvh", "no such file"),
    ("methods-bad", f"motion {A} --methods controller nosuch", "unknown method"),
    ("library-bad", f"motion {A} --library {{lib.npz_truncated}}", "damaged motion library"),
    ("inference-held-out-0", f"inference {P} --held-out 0", "--held-out must be"),
    ("inference-held-out-nan", f"inference {P} --held-out nan", "--held-out must be"),
    ("inference-windows-neg", f"inference {P} --windows -1", "--windows must be"),
    ("inference-windows-17", f"inference {P} --windows 17", "--windows must be"),
    ("inference-clusters-1", f"inference {P} --clusters 1", "--clusters must be"),
    ("inference-seed-neg", f"inference {P} --seed -1", "--seed must be"),
    ("inference-pair-missing", "inference --pair /no/m.bvh /no/a.wav", "no such file"),
]:
    row(f"eval-{id_}", f"eval {args}", 2, msg, ("{out.file_report}", A))

# ------------------------------------------------------------------ live (argument checks)
for id_, args, msg in [
    ("style-5", "--style 5", "--style must be"), ("style-nan", "--style nan", "--style must be"),
    ("fps-0", "--fps 0", "--fps must be"), ("fps-nan", "--fps nan", "--fps must be"),
    ("fps-inf", "--fps inf", "--fps must be"), ("duration-0", "--duration 0",
                                                "--duration must be"),
    ("duration-nan", "--duration nan", "--duration must be"),
    ("duration-inf", "--duration inf", "--duration must be"),
    ("duration-neg", "--duration -5", "--duration must be"),
    ("seed-neg", "--seed -1", "--seed must be"),
    ("audio-missing", "--audio /no/such.wav", "no such file"),
    ("audio-folder", "--audio {out.dir_mp4}", "is a folder"),
    ("audio-dev-zero", "--audio /dev/zero", "is a device"),
    ("audio-nan", "--audio {audio.nan}", "NaN or infinite"),
    ("audio-empty", "--audio {audio.empty}", "empty file"),
    ("loop-without-audio", "--loop", "--loop and --mute need --audio"),
    ("screenshot-folder", f"--audio {A} --screenshot {{out.dir_png}}", "is an existing folder"),
    ("screenshot-txt", f"--audio {A} --screenshot {{new}}/s.txt", "unsupported file type"),
    ("stats-folder", f"--audio {A} --stats {{out.dir_json}}", "is an existing folder"),
    ("stats-is-input", f"--audio {A} --stats {A}", "is the input file"),
    ("library-missing", f"--audio {A} --library /no/lib", "no such folder"),
]:
    row(f"live-{id_}", f"live {args}", 2, msg, (A,))

# ------------------------------------------------------------------ bench (argument checks)
for id_, args, msg in [
    ("control-lengths-0", "control --lengths 0", "--lengths must be"),
    ("control-lengths-neg", "control --lengths -5", "--lengths must be"),
    ("control-lengths-nan", "control --lengths nan", "--lengths must be"),
    ("control-lengths-inf", "control --lengths 51 inf", "--lengths must be"),
    ("control-states-0", "control --states 0", "--states must be"),
    ("control-decisions-0", "control --decisions 0", "--decisions must be"),
    ("physics-duration-0", "physics --duration 0", "--duration must be"),
    ("physics-duration-nan", "physics --duration nan", "--duration must be"),
    ("physics-duration-inf", "physics --duration inf", "--duration must be"),
    ("physics-control-every-0", "physics --control-every 0", "--control-every must be"),
    ("physics-seed-neg", "physics --seed -1", "--seed must be"),
    ("prosody-block-0", "prosody --block-size 0", "--block-size must be"),
    ("prosody-repeat-0", "prosody --repeat 0", "--repeat must be"),
    ("prosody-missing-file", "prosody /no/such.wav", "no such file"),
    ("render-seconds-0", "render --seconds 0", "--seconds must be"),
    ("render-seconds-nan", "render --seconds nan", "--seconds must be"),
    ("render-fps-nan", "render --fps nan", "--fps must be"),
    ("pipeline-missing-file", "pipeline /no/such.wav", "no such file"),
    ("inference-steps-0", "inference --steps 0", "--steps must be"),
]:
    row(f"bench-{id_}", f"bench {args}", 2, msg)
row("train-pair-unknown-skeleton",
    "train --pair {motion.bvh_unknown_skeleton} {audio.good} -o {new}/m", 2,
    "good.wav: unknown skeleton")

# ------------------------------------------------------------------ inputs other than the audio
# (issue 27, sweep defect 1): every input path is protected from every output
IN_ROWS = [
    ("render-metrics-is-keywords",
     f"render {A} -o {NEW_MP4} --keywords {{in.keywords}} --metrics {{in.keywords}}",
     "is the input file", ("{in.keywords}",)),
    ("render-metrics-in-library",
     f"render {A} -o {NEW_MP4} --library {{in.library}} --metrics {{in.manifest}}",
     "is the input file", ("{in.manifest}", "{in.library_npz}")),
    ("render-timeline-is-transcript",
     f"render {A} -o {NEW_MP4} --transcript {{in.keywords}} --timeline {{in.keywords}}",
     "is the input file", ("{in.keywords}",)),
    ("graph-o-is-library-npz", "library graph {in.library} -o {in.library_npz}",
     "is the input file", ("{in.library_npz}", "{in.manifest}")),
    ("build-o-holds-input", "library build {in.holder_bvh} -o {in.holder}",
     "holds the input", ("{in.holder_bvh}",)),
    ("eval-report-is-library", f"eval motion {A} --library {{in.library}} --report {{in.library}}",
     "is the input file", ("{in.manifest}", "{in.library_npz}")),
]
for id_, cmd, msg, keep in IN_ROWS:
    row(f"inputs-{id_}", cmd, 2, msg, keep)
