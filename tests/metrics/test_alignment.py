"""Known answers of the token alignment behind the word and phone error rates of the tools."""

from gesture_sim.metrics.alignment import edit_ops


def test_edit_ops_counts_each_kind_of_error_and_pairs_the_matches():
    ref = "the cat sat on the mat".split()
    assert edit_ops(ref, ref) == (0, [(i, i) for i in range(6)])
    assert edit_ops("a b c".split(), "a c".split()) == (1, [(0, 0), (2, 1)])      # deletion
    assert edit_ops("a c".split(), "a b c".split()) == (1, [(0, 0), (1, 2)])      # insertion
    assert edit_ops("a b".split(), "a x".split()) == (1, [(0, 0)])                # substitution
    dist, pairs = edit_ops(ref, "the hat sat the big mat".split())
    assert dist == 3
    assert all(ref[i] == h for i, h in ((i, "the hat sat the big mat".split()[j])
                                        for i, j in pairs))
    assert edit_ops([], ["a", "b"]) == (2, [])
    assert edit_ops(["a", "b"], []) == (2, [])
