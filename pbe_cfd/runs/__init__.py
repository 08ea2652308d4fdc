"""A run: the scene's arrays, the cell batches, well-mixed and coupled runs, executors."""
