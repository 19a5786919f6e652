"""Post-processing of trajectories: contact forces, summaries, spectra, plots."""

from .contact_forces import clearance_joint_history

__all__ = ["clearance_joint_history"]
