"""``rrtq bench``: the Monte Carlo bench over seeds, random layouts and configurations.

:mod:`.monte_carlo` is the command (it prepares the runs and writes the tables);
:mod:`.layouts` draws the random obstacle layouts, :mod:`.sweep` the configurations of
``--set``; :mod:`.local_engine` and :mod:`.ray_engine` run the jobs; :mod:`.control`
reads how the controller flew each run, :mod:`.table` and :mod:`.sweep_table` aggregate
the rows into the tables.
"""
