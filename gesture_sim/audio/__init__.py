"""Audio sources (file, microphone) and the causal prosody tracker."""
