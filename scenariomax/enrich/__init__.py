"""Scenario enrichment: roadgraph sampling, budgets, SDC paths, controllable labels, light inference."""
