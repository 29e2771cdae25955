"""Widgets of the operator TUI (one job each; screens compose them)."""
