"""evo's commands on epica's maths: ``protocol`` (evo_ape / evo_rpe semantics), ``commands``
(``epa ape|rpe|res``), ``archive`` (evo's result zip, written and read), ``plots`` (evo's two
figures of a result)."""

__all__ = ["archive", "commands", "plots", "protocol"]
