"""Metrics as functions on arrays: physical plausibility (:mod:`.physics`), motion quality and
coupling (:mod:`.motion`, :mod:`.points`, :mod:`.reference`, :mod:`.summary`), selection
(:mod:`.selection`), head and face (:mod:`.face`), conversations (:mod:`.conversation`), and the
inputs they need (:mod:`.inputs`). Nothing here imports the pipeline or the loader."""
