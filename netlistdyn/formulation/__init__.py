"""From a netlist to equations: normal tree, reduction, descriptor and nonlinear systems."""
