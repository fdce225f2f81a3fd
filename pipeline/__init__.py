"""pipeline: ensembles, storage, statistics, plots and the rss6 command line."""
