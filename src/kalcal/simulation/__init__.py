"""Random realizations: an explicit numpy Generator in, arrays out."""
