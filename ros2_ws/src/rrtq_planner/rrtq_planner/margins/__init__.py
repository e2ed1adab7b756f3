"""Safety margins that tighten with evidence (issue 11; derivations in ``docs/margins.md``).

:mod:`.policy` is the interface the safety side feeds once per step (:func:`.build.make_policy`
makes one); the modes are ``running_max`` (RRT-QX eqs. 6-7, the paper's), ``conformal``
(:mod:`.conformal`) and ``learned_bound`` (Jha: :mod:`.learned`, its margins
:mod:`.learned_margin` and its data :mod:`.learned_data`, from :mod:`.regression`, :mod:`.bank`,
:mod:`.tube`). :mod:`.calibration` reads and writes the scores a run carries
to the next; :mod:`.coverage` gives binomial intervals for checking them; :mod:`.observer`
is the recursive least-squares model the joint fit of :mod:`.learned` is compared with.
"""
