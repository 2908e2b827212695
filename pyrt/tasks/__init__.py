"""Self-scheduling tasks built over the robots: database write-back, server poll, scope sampler."""
