"""A lab's archive as one batch: every run x gyro replayed, identified and diagnosed as
Dask tasks, one fleet table, a fleet view.

* :mod:`.inputs` — what the batch runs on: run folders, raw logs (each with the session
  file that decodes it), globs, a manifest CSV of run attributes;
* :mod:`.tasks` — the one task a worker runs per run (the adapter onto gyrostand's
  replay / identify / diagnose), its result written atomically under the batch folder;
* :mod:`.runner` — the client side: skip what is done, submit the rest to a Dask
  scheduler, count done / failed / remaining;
* :mod:`.table` — the fleet table (CSV, Parquet), one row per run x gyro;
* :mod:`.fleet` — outliers, spreads, trends and the HTML page.

Nothing here imports Dask at module level: only :mod:`.runner` does, inside its functions,
so ``gyrostand --help`` stays light and the table/fleet code works without Dask.
"""
