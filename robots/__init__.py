"""URDFs of the arms bundled with nearopt (loaded by name, e.g. ``Robot.from_name("two_link")``)."""
