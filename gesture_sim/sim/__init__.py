"""The simulated humanoid: model access (:mod:`.humanoid`), scenes of several (:mod:`.scene`),
target streams and the shaper (:mod:`.targets`), target layers (:mod:`.layers`), PD + balance
tracking (:mod:`.tracking`), the one stepping loop (:mod:`.world`) and the trace (:mod:`.trace`)."""
