"""Reading SPICE text into a :class:`~netlistdyn.circuit.netlist.Netlist`."""
