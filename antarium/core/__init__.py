"""The ground floor: what every stage shares (clock, pose, ball, the dome's rate, real-time placement, child
processes). Pure Python and numpy; `antarium.firmware_proto` and `antarium.renderers` may import it."""
