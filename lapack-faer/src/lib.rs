//! Fortran-ABI BLAS/LAPACK symbols (dsyevr_, dpotrf_, ...) implemented with faer, so that clarabel's `sdp`
//! feature links without a system BLAS/LAPACK.
