"""FicTrac (Moore et al. 2014) as a locomotion source: its line format, and the live and replay sources."""
