"""The configuration of a run: the group table and the study's named readings."""
