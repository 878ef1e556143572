"""What a person or another program reads: reports, exports, plots, animations."""
