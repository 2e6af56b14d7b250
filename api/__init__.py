"""HTTP service for the map matcher."""
