// The solvers tfmatch offers, listed explicitly (no static registration: a solver exists because
// it is in this list, whatever the linker keeps).
#pragma once

#include "optimize.h"

namespace tfm {

SolverOutput run_normal_equations_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_cgls_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_diffdvr_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_eigen_normal_equations_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_eigen_cgls_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_gradient_descent_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_qp_solver(VoxelProblem& problem, const SolverSettings& settings);
#ifdef TFMATCH_HAVE_CUDA
SolverOutput run_cuda_normal_equations_solver(VoxelProblem& problem, const SolverSettings& settings);
SolverOutput run_cuda_cgls_solver(VoxelProblem& problem, const SolverSettings& settings);
#endif

}  // namespace tfm
