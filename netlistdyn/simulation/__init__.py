"""Time responses: input signals, exact and rational stepping, transients."""
