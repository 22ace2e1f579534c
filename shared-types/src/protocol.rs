//! UART protocol between the plant (host) and the firmware: COBS-framed postcard messages carrying a
//! sequence number and the state, answered by the input, a status and the step's cost.
