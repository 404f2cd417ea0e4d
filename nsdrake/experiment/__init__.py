"""A scenario from file to traces: the scenario types and their YAML reader, the
references (the paper's Fig. 3 task, a circle on a surface), the checks made before a
run, the diagram's assembly, the simulation, the traces, and the output folders."""
