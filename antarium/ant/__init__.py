"""The virtual ant: a panoramic eye and mushroom-body navigation models in the closed loop."""
