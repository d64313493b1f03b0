"""The virtual ant: a panoramic eye and mushroom-body navigation models in the closed loop."""

#: the models that learn a route by its views and follow it (`antarium.ant.route_following`; `antarium ant learn | run
#: | evaluate | experiment`); the central-complex models home by path integration instead (`antarium.ant.homing`)
ROUTE_MODELS = ("antcar", "ardin", "perfect_memory")
