"""Control layer: which segment plays, and when.

Modules: :mod:`.inputs` (plain-array views of the library and model, adapters),
:mod:`.costs` (eta, switch costs, settings), :mod:`.mdp` (semi-MDP value iteration),
:mod:`.policy` (training, decomposed candidate lists, npz storage),
:mod:`.prune` (exact dominance pruning without the full value table),
:mod:`.controller` (online MDP decisions), :mod:`.mimic` (Okwechime 2011's motion graph),
:mod:`.baselines` (random choice), :mod:`.synchrony` (the timing layer: strokes on accents,
holds, rest, energy), :mod:`.ramp` (the one switch ramp), :mod:`.protocols` (the interfaces
the method registry builds on) and :mod:`.style` (tones, style dial).
"""
