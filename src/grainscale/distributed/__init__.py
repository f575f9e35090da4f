"""Distributed runs over MPI ranks: the communicator wrapper and the point ownership."""
