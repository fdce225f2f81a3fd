"""Ensemble execution: the clearance draws (Monte Carlo or scrambled Sobol'), the settings a run
resolves once, and the dask runs that compute, store and resume chunks of realisations."""
