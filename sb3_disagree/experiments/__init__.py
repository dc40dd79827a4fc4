"""Multi-seed experiments: training curves from run folders, aggregation and plots."""
