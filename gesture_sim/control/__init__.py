"""Control layer: segment costs, MDP value iteration, the online gesture controller.

Modules: :mod:`.inputs` (plain-array views of the library and model, adapters),
:mod:`.costs` (eta, switch costs, settings), :mod:`.mdp` (semi-MDP value iteration),
:mod:`.policy` (training, decomposed candidate lists, npz storage),
:mod:`.prune` (exact dominance pruning without the full value table),
:mod:`.controller` (online decisions),
:mod:`.offline` (§7.1 dynamic programming), :mod:`.style` (tones, style dial) and
:mod:`.synthetic` (synthetic libraries/models for tests and benchmarks).
"""
