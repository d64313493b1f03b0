"""Model experiments at scale: real routes and worlds, a TOML spec expanded into runs, run on Dask, resumable."""
