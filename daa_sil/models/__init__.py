"""Stochastic models of the study (sans-IO, seeded, batched): the remote pilot, link latency, the paper's Table 6 encounters."""
