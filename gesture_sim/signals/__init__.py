"""Face and head conversational signals timed to the speech (after RUTH, DeCarlo et al. 2004)."""
