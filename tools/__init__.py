"""Scripts that maintain the checkout (not part of the installed package)."""
