"""Running the stages: one module per stage (``stages/``, each declaring itself), the chain that
derives the rest from the declarations (``chain``), batches and jobs (``jobs``), discovery of cases
(``discovery``), the schema-validated settings (``settings``) and the recovery check of Steps 1-2
(``recovery``)."""

__all__ = ["chain", "discovery", "jobs", "recovery", "settings"]
