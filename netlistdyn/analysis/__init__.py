"""What a model says: eigenvalues and their checks, control properties, coordinates."""
