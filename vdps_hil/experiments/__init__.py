"""Everything that reads simulator truth or scores against it (never imported by the pipeline packages)."""
