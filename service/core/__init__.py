"""Service core: configuration."""
