"""Tesollo Delto grippers: developer-mode TCP protocol (codec), driver and model table."""
