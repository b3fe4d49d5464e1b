"""Applications: video render (:mod:`.render`, :mod:`.video`, :mod:`.camera`), the live viewer
(:mod:`.live`, :mod:`.viewer`, :mod:`.overlay`, :mod:`.live_stats`, :mod:`.listening`), the
timeline figure (:mod:`.timeline`), conversations (:mod:`.conversation`), motion exports
(:mod:`.motion_export`), the evaluation runner and its reports (:mod:`.evaluation`,
:mod:`.report`) and batches (:mod:`.batch`, :mod:`.cpus`)."""
