"""Geometry of an encounter (sans-IO, vectorised): units, frames, threshold presets, DO-365 well clear, kinematics."""
