"""Pictures: plots, the PSD figure, rendered fields and sections."""
