//! Aerial orthomap layers, PNG compression for transmission, goal detection and placement.
