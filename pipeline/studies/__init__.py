"""Studies built on ensembles: speed against accuracy, stability, Sobol' sensitivity, clearance
budgets, multi-fidelity means, the acceleration study and the report."""
