"""Small helpers shared by every layer: progress lines, particle populations."""
