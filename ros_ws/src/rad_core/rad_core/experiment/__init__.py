"""Evaluation of agents on scene sets (`evaluation`) and its scale-out on Dask (`distributed`)."""
