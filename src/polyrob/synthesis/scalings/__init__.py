"""D and G scalings of μ-synthesis: data from the μ sweep, magnitude and phase fits, the scaled plant."""
