"""The state-space model x' = Ax + Bu, y = Cx + Du and its interconnection."""
