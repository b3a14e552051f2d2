"""Detection probability as a cost (issue 43): radar model, hazard, its plan (imports: methods)."""
