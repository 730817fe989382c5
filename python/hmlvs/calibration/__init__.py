"""Parameter identification: the solvers facade (PSO, LM, random search) and its results."""
