"""The mesh model, its edge table and checks, format sniffing, progress: what every other wing builds on."""
