"""Audio sources and the causal speech analysis.

Modules: :mod:`~gesture_sim.audio.sources` (``load_audio``, ``iter_blocks``, microphone),
:mod:`~gesture_sim.audio.feeds` (the live loop's feeds), :mod:`~gesture_sim.audio.prosody`
(``ProsodyTracker``), :mod:`~gesture_sim.audio.accents` (``AccentDetector``: accents,
boundaries, voice activity, energy), :mod:`~gesture_sim.audio.speech` (``SpeechState``: the one
view per control step), :mod:`~gesture_sim.audio.vad`, :mod:`~gesture_sim.audio.keywords` and
:mod:`~gesture_sim.audio.utterances` (PocketSphinx spotting and confirmation),
:mod:`~gesture_sim.audio.textgrid`, :mod:`~gesture_sim.audio.turns` (who speaks when) and
:mod:`~gesture_sim.audio.plot`. The inference featuriser (``SpeakerNormalizer``,
``levine09_features``) lives in :mod:`gesture_sim.inference.normalize`.
"""
