"""A run's analysis as the user sees it: ``analyze`` measures a run (``analyze_run``) and pairs
each measurement with its model's prediction (``theory_comparison``); ``summary`` prints its
headline, ``export`` writes analysis.nc, JSON and CSV, ``figures`` draws it."""
