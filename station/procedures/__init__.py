"""UI-free procedure logic shared by the CLI and the TUI."""
