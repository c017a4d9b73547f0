"""The node's topics: the input topics and their pairing (inputs), latched results built on
demand (on_demand), /diagnostics (diagnostics) and the quality-of-service profiles (qos)."""
