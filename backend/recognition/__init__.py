"""Object models and trained views in the running system: the database service, the live
index built from it at start-up and kept in step with every change, the teach job and the
automatic threshold (the algorithms live in ``vision.recognition``)."""
