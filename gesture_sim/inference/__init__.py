"""Inference layer: kinematic HMM, prosody clusters, remapped CRF, Levine 2009 baseline.

Run time (what the pipeline uses)::

    from gesture_sim.inference.model import GestureModel
    model = GestureModel.load("motion_library/default/model")
    filt = model.new_filter()            # or model.new_filter("levine09") for the baseline
    belief = filt.step(t, new_syllables)  # once per control step; (S,), sums to 1

``model.hmm.means`` (S, 6) / ``model.hmm.covars`` (S, 6, 6) are the states' Gaussians over the
normalised kinematic parameters (T, D, V, A, C, H); ``model.transition_matrix`` (S, S) is
row-stochastic. Modules: :mod:`.features` (per-step X and Y), :mod:`.clusters`, :mod:`.hmm`,
:mod:`.crf`, :mod:`.chain` (log-space forward-backward), :mod:`.levine09`, :mod:`.model`,
:mod:`.train`, :mod:`.evaluate` (Fig. 4).
"""
