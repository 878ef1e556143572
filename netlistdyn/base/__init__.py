"""Foundations every layer may use: errors, SPICE numbers, formatting, atomic files, processes, progress."""
