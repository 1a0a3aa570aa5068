"""What a system is: immutable descriptions, no algorithms."""
