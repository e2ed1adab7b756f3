"""``rrtq report RUN.mcap``: figures and a summary of a run, from its recording alone.

:mod:`.run` writes them (map, time series, legs, ``summary.json``); :mod:`.margins` and
:mod:`.vf_lpc` add the margin figures and the vf_lpc run's; :mod:`.video` is ``--video``.
"""
