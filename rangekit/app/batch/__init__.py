"""Many sessions on Dask (`rangekit process A B ...`): sessions (`process_sessions`: a task per view's decoding,
then one per session, each placed by the runner's Dask plan) and pairs (a task per view pair's refinement)."""
