"""Measuring a policy on episodes: rollouts, the evaluation report, the metric registry, the correction
test's quota and the generalisation splits. Knows nothing of how the policy was trained."""
