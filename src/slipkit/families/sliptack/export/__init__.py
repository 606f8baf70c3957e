"""SlipTack's exporters: the speed graph (:mod:`.speed`), its slip decision
(:mod:`.detector`), the onset, spectral and torsional graphs, and the parity benchmark
(:mod:`.parity`)."""
