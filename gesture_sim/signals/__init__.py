"""Face and head conversational signals timed to the speech (after RUTH, DeCarlo et al. 2004:
:mod:`.ruth`) and the listener's backchannels (Okwechime 2011: :mod:`.listener`), as offsets
for target layers."""
