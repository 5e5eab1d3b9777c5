"""Zenoh plumbing of the ASNN service: messages, keys, configuration, camera, worker."""
