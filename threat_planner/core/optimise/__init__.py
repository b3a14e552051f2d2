"""Smoothing (§3.4), L-BFGS, flight limits, augmented Lagrangian (imports: cost, world)."""
