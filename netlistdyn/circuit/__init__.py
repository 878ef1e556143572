"""The netlist as data: elements, waveforms, expressions, output probes."""
