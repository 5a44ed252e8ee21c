"""Packaged vehicle parameter files (TOML), loaded by :func:`ptw_env.vehicle_files.load_vehicle`."""
