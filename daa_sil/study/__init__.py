"""The fast-time study (sans-IO): batched simulation, campaigns over groups, statistics, metrics, findings, the report."""
