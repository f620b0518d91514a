"""The crane's observation camera: its bird's-eye video onto the bus."""
