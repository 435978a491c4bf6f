//! Sparkplug B 3.0: the payload, the topics, and values to and from metrics.
