"""The Antarium's geometry: the dome solid, its panels, the LED layout and every LED's address (pure numpy)."""
