"""The configuration of a run: :mod:`~daa_sil.config.run_config` (one object, presets, YAML), the
group table (:mod:`~daa_sil.config.groups`, data in ``daa_sil/data/groups.yaml``) and the study's
named readings (:mod:`~daa_sil.config.readings`)."""
