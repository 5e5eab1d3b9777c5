"""Consumers of the ASNN service: warning subscribers and the fleet dashboard."""
