"""selpres's Hydra sweeper plugin: the Optuna sweeper searching schedules (see selpres_search.py)."""
