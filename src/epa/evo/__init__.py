"""evo's commands on epica's maths: ``protocol`` (evo_ape / evo_rpe semantics), ``commands``
(``epa ape|rpe|res``)."""

__all__ = ["commands", "protocol"]
