"""Glue for outside learners: gymnasium wrappers that read the instruction as words, and a
stable-baselines3 features extractor."""
