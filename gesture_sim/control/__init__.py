"""Control layer: segment costs, MDP value iteration, the online gesture controller."""
