"""Running the stages: one module per stage (``stages/``), the chain that orders them and the
per-case cache (``chain``), batches and jobs (``jobs``), discovery of cases (``discovery``), the
schema-validated settings (``settings``) and the recovery check of Steps 1-2 (``recovery``)."""

__all__ = ["chain", "discovery", "jobs", "recovery", "settings"]
