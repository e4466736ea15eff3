"""The ports: what the runtime loops need from the world (vehicle, bus, events, clock), declared
here so that runtime sees them without importing the adapters that implement them."""
