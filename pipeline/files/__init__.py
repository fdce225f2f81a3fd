"""Files: the netCDF schema (names, units, CF encoding), writing and reading with checksums, the
checks a file must pass before it is used, and the output paths, locks and parts manifests.

Each module imports only those before it: schema < records < checksums < writing < outputs < reading
< check < opening (read, then checked); outputs (paths, locks, manifests) uses schema and writing, and
reading asks it why a file a run has not written yet is missing; error_map (the workspace error
map's file, ``rss6 map``) uses none of them."""
