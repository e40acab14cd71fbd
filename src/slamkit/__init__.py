"""slamkit."""
