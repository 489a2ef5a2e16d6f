"""Gymnasium environments built on tianim. Importing this package registers them."""
