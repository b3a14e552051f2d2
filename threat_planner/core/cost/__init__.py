"""J = w*J_R + (1-w)*J_L: closed form, compiled kernels, cut-off, masking (imports: world)."""
