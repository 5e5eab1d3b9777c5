"""The ``asnn`` command line: the top layer, importing asnn, service and clients."""
