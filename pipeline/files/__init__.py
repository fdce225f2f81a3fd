"""Files: the netCDF schema (names, units, CF encoding), writing and reading with checksums, the
checks a file must pass before it is used, and the output paths, locks and parts manifests."""
