"""Audio sources (file, microphone) and the causal prosody tracker.

Modules: :mod:`~gesture_sim.audio.sources` (``load_audio``, ``FileSource``,
``MicrophoneSource``, ``list_input_devices``), :mod:`~gesture_sim.audio.prosody`
(``ProsodyTracker``, ``analyze_file``) and :mod:`~gesture_sim.audio.plot` (``plot_prosody``).
The inference featuriser (``SpeakerNormalizer``, ``levine09_features``) lives in
:mod:`gesture_sim.inference.normalize`.
"""
