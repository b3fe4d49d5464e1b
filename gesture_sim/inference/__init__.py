"""Inference layer: kinematic HMM, prosody clusters, remapped CRF, Levine 2009 baseline."""
